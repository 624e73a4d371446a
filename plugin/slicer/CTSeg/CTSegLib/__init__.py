"""GUI-free part of the CTSeg module (see logic.py)."""
