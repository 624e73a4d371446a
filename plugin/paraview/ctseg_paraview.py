"""ParaView plugin for ctseg: the composite segmentation filter and the stage filters of
``ctseg.filters`` in the Filters menu, category "ctseg".

Load it with Tools > Manage Plugins > Load New... (this file), or put this folder on
PV_PLUGIN_PATH. ParaView's Python must be able to import ctseg and its dependencies (see
the README's ParaView section). This file only declares the ParaView proxies: every filter
is a ``ctseg.filters`` class, unchanged; the algorithms live in ``ctseg``. In
``paraview.simple`` the filters are CTSegment, CTMetalStreaks, CTDensityMap, CTCVTSites, CTDelaunayMesh,
CTTriangleGray, CTGraphCut and CTMaterialBoundary.
"""
from paraview.util.vtkAlgorithm import smdomain, smhint, smproperty, smproxy

from ctseg.filters import (CTSegmentFilter, CVTSitesFilter, DelaunayMeshFilter,
                           DensityMapFilter, GraphCutSegmentFilter, MaterialBoundaryFilter,
                           MetalStreakFilter, TriangleGrayFilter)

MENU = '<ShowInMenu category="ctseg"/>'
AXES = ("z", "y", "x")
INITS = ("ward", "random", "density_random")


def _doc(text):
    return smdomain.xml(f"<Documentation>{text}</Documentation>")


def _enum(names):
    entries = "".join(f'<Entry value="{k}" text="{n}"/>' for k, n in enumerate(names))
    return smdomain.xml(f'<EnumerationDomain name="enum">{entries}</EnumerationDomain>')


def _number(kind, name, default, low, high, doc, apply):
    """An int or float property with a range, calling ``apply(self, value)``."""
    vector, domain = ((smproperty.intvector, smdomain.intrange) if kind is int
                      else (smproperty.doublevector, smdomain.doublerange))

    @vector(name=name, command=f"Set{name}", default_values=[default])
    @domain(min=low, max=high)
    @_doc(doc)
    def setter(self, value):
        apply(self, kind(value))
    return setter


def _int(*args):
    return _number(int, *args)


def _double(*args):
    return _number(float, *args)


def _choice(name, names, default, doc, apply):
    @smproperty.intvector(name=name, command=f"Set{name}", default_values=[default])
    @_enum(names)
    @_doc(doc)
    def setter(self, value):
        apply(self, names[int(value)])
    return setter


def _param(key, auto_zero=False):
    """Apply to a keyword of ctseg.segment_image; 0 means 'from the data' where it may."""
    def apply(self, value):
        self.SetParameter(key, None if auto_zero and value == 0 else value)
    return apply


def _stage(name, label, *inputs):
    """Declare a stage filter: its proxy, the ctseg menu, and its inputs as
    (port name, port index, data type), in port order."""
    def decorate(cls):
        for port, index, data_type in inputs:
            cls = smdomain.datatype(dataTypes=[data_type], composite_data_supported=False)(cls)
            cls = smproperty.input(name=port, port_index=index)(cls)
        return smproxy.filter(name=name, label=label)(smhint.xml(MENU)(cls))
    return decorate


@smproxy.filter(name="CTSegment", label="CT Segment")
@smhint.xml(MENU)
@smproperty.xml('<OutputPort name="Mesh" index="0"/>')
@smproperty.xml('<OutputPort name="Boundaries" index="1"/>')
@smproperty.input(name="Input", port_index=0)
@smdomain.datatype(dataTypes=["vtkImageData"], composite_data_supported=False)
class CTSegment(CTSegmentFilter):
    """CT slice or volume -> triangle mesh with one material per triangle
    (Yang et al. 2014); volumes slice by slice with one material numbering."""

    SetNumberOfSites = _int("NumberOfSites", 0, 0, 1000000,
                            "CVT sites (mesh vertices) per slice; 0 = one per 128 pixels.",
                            CTSegmentFilter.SetNumberOfSites)
    SetSeed = _int("Seed", 0, 0, 2 ** 31 - 1, "Seed of the random initialisations.",
                   CTSegmentFilter.SetSeed)
    SetNumberOfMaterials = _int("NumberOfMaterials", 0, 0, 32,
                                "Exact number of materials; 0 = found from the data.",
                                CTSegmentFilter.SetNumberOfMaterials)
    SetSliceAxis = _choice("SliceAxis", AXES, 0, "Axis along which a volume is sliced.",
                           CTSegmentFilter.SetSliceAxis)
    SetNumberOfJobs = _int("NumberOfJobs", 1, 0, 256,
                           "Worker processes for a volume's slices (1 = in ParaView's "
                           "process, 0 = one per core).", CTSegmentFilter.SetNumberOfJobs)
    SetInitialization = _choice("Initialization", INITS, 0,
                                "Initial CVT sites: Ward's clustering (the paper), uniform "
                                "random, or random by density.", _param("init"))
    SetSigma = _double("Sigma", 1.0, 0.0, 10.0, "Gaussian pre-smoothing of the density "
                       "map, pixels.", _param("sigma"))
    SetDensityFloor = _double("DensityFloor", 0.02, 1e-6, 1.0, "Density added everywhere "
                              "so that flat regions keep sites.", _param("density_floor"))
    SetDensitySaturation = _double("DensitySaturation", 0.0, 0.0, 1.0,
                                   "Gradient that gets the full density, as a fraction of "
                                   "the largest; 0 = from the noise (auto), 1 = the paper's "
                                   "normalisation.",
                                   lambda self, v: self.SetParameter("density_saturation",
                                                                     "auto" if v == 0 else v))
    SetDensityRidge = _double("DensityRidge", 2.0, 0.0, 8.0, "Ridge sharpening exponent "
                              "(0 = the paper's map).", _param("density_ridge"))
    SetWardBlockPixels = _int("WardBlockPixels", 0, 0, 64, "Ward pre-merge block size in pixels "
                        "(0 = automatic, 1 = exact Ward).", _param("ward_block_px", True))
    SetTolerance = _double("Tolerance", 0.01, 1e-6, 10.0, "Lloyd stops when no site moves "
                           "more than this, pixels.", _param("tol_px"))
    SetMaximumIterations = _int("MaximumIterations", 200, 1, 100000, "Lloyd iteration cap.",
                                _param("max_iter"))
    SetLambda = _double("Lambda", 70.0, 0.0, 1e6, "Weight of the neighbour terms of the "
                        "graph cut (paper: 70).", _param("lam"))
    SetBeta = _double("Beta", 0.286, 0.0, 100.0, "Weight of the distance term of the "
                      "neighbour capacities (paper: 0.286).", _param("beta"))
    SetTheta = _double("Theta", 0.0, 0.0, 255.0, "Seed-set width of the graph cut, gray "
                       "levels on 0-255; 0 = 10% of the component's range.",
                       _param("theta", True))
    SetStepThreshold = _double("StepThreshold", 0.0, 0.0, 255.0, "Gray step (0-255) above "
                               "which a triangle straddles a boundary; 0 = from the noise.",
                               _param("step_threshold", True))
    SetMergeK = _double("MergeK", 5.0, 0.0, 100.0, "Materials closer than MergeK noise "
                        "sigmas (+ MergeRel x gray) are one.", _param("merge_k"))
    SetMergeRel = _double("MergeRel", 0.2, 0.0, 10.0, "Gray-proportional part of the "
                          "material separation (beam hardening).", _param("merge_rel"))
    SetMergeFloor = _double("MergeFloor", 2.0, 0.0, 255.0, "Smallest material separation, "
                            "gray levels on 0-255.", _param("merge_floor"))
    SetMergeThreshold = _double("MergeThreshold", 0.0, 0.0, 255.0, "Fixed material "
                                "separation (0-255) instead of the rule above; 0 = off.",
                                _param("merge_threshold", True))
    SetMinTriangles = _int("MinTriangles", 2, 1, 1000000, "Components smaller than this "
                           "are not split further.", _param("min_triangles"))
    SetMaxDepth = _int("MaxDepth", 32, 0, 1000, "Recursion depth cap of the graph cuts.",
                       _param("max_depth"))
    SetMinMaterialArea = _double("MinMaterialArea", 0.0, 0.0, 1e12, "Interior area (px) a "
                                 "gray mode needs to be a material; 0 = automatic.",
                                 _param("min_material_area", True))
    SetMinPocketArea = _double("MinPocketArea", 4.0, 0.0, 1e12, "Interior area (px) of a "
                               "material that makes a component worth splitting.",
                               _param("min_pocket_area"))
    SetWeightByEdgeLength = _int("WeightByEdgeLength", 0, 0, 1, "Multiply neighbour "
                                 "capacities by the shared edge length (not the paper's).",
                                 lambda self, v: self.SetParameter("weight_by_edge_length", bool(v)))
    SetStreakCorrection = _int("StreakCorrection", 1, 0, 1, "First remove the dark "
                               "beam-hardening streaks next to metal (not the paper's).",
                               lambda self, v: self.SetParameter("streak_correction", bool(v)))
    SetBlurCorrection = _int("BlurCorrection", 1, 0, 1, "Take off the edge blur the first "
                             "labelling predicts and label again (not the paper's).",
                             lambda self, v: self.SetParameter("blur_correction", bool(v)))


@_stage("CTMetalStreaks", "CT Metal Streaks", ("Input", 0, "vtkImageData"))
class CTMetalStreaks(MetalStreakFilter):
    """First stage (not in the paper): the slice with the beam-hardening streaks of its
    densest material removed; the input values kept as an 'original' point array."""

    SetSigma = _double("Sigma", 1.0, 0.0, 10.0, "Gaussian smoothing before pixels are "
                       "classified, pixels.", MetalStreakFilter.SetSigma)


@_stage("CTDensityMap", "CT Density Map", ("Input", 0, "vtkImageData"))
class CTDensityMap(DensityMapFilter):
    """Stage 1: the gradient density map of a slice, as a 'density' point array."""

    SetSigma = _double("Sigma", 1.0, 0.0, 10.0, "Gaussian pre-smoothing, pixels.",
                       DensityMapFilter.SetSigma)
    SetFloor = _double("Floor", 0.02, 1e-6, 1.0, "Density added everywhere.",
                       DensityMapFilter.SetFloor)
    SetSaturation = _double("Saturation", 0.0, 0.0, 1.0, "Fraction of the largest gradient "
                            "that gets the full density; 0 = from the noise (auto).",
                            lambda self, v: DensityMapFilter.SetSaturation(
                                self, "auto" if v == 0 else v))
    SetRidge = _double("Ridge", 2.0, 0.0, 8.0, "Ridge sharpening exponent (0 = off).",
                       DensityMapFilter.SetRidge)


@_stage("CTCVTSites", "CT CVT Sites", ("Input", 0, "vtkImageData"))
class CTCVTSites(CVTSitesFilter):
    """Stages 2-3: Ward-initialised CVT of a density map; the sites as vertices."""

    SetNumberOfSites = _int("NumberOfSites", 0, 0, 1000000, "0 = one per 128 pixels.",
                            CVTSitesFilter.SetNumberOfSites)
    SetSeed = _int("Seed", 0, 0, 2 ** 31 - 1, "Seed of the random initialisations.",
                   CVTSitesFilter.SetSeed)
    SetInitialization = _choice("Initialization", INITS, 0, "Initial sites.",
                                CVTSitesFilter.SetInitialization)
    SetTolerance = _double("Tolerance", 0.01, 1e-6, 10.0, "Lloyd stopping move, pixels.",
                           CVTSitesFilter.SetTolerance)
    SetMaximumIterations = _int("MaximumIterations", 200, 1, 100000, "Lloyd iteration cap.",
                                CVTSitesFilter.SetMaximumIterations)


@_stage("CTDelaunayMesh", "CT Delaunay Mesh", ("Input", 0, "vtkPolyData"))
class CTDelaunayMesh(DelaunayMeshFilter):
    """Stage 4: the Delaunay triangles of the CVT sites."""


@_stage("CTTriangleGray", "CT Triangle Gray", ("Mesh", 0, "vtkPolyData"), ("Image", 1, "vtkImageData"))
class CTTriangleGray(TriangleGrayFilter):
    """Stage 5: exact area-weighted mean gray of every triangle over the image."""


@_stage("CTGraphCut", "CT Graph Cut", ("Mesh", 0, "vtkPolyData"), ("Image", 1, "vtkImageData"))
class CTGraphCut(GraphCutSegmentFilter):
    """Stages 6-7: recursive graph cut of the triangles into materials."""

    SetNumberOfMaterials = _int("NumberOfMaterials", 0, 0, 32, "0 = found from the data.",
                                GraphCutSegmentFilter.SetNumberOfMaterials)
    SetLambda = _double("Lambda", 70.0, 0.0, 1e6, "Neighbour term weight (paper: 70).",
                        GraphCutSegmentFilter.SetLambda)
    SetBeta = _double("Beta", 0.286, 0.0, 100.0, "Distance term weight (paper: 0.286).",
                      GraphCutSegmentFilter.SetBeta)


@_stage("CTMaterialBoundary", "CT Material Boundary", ("Input", 0, "vtkPolyData"))
class CTMaterialBoundary(MaterialBoundaryFilter):
    """The edges between materials as polylines with the materials each side."""
