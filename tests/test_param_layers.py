"""Every layer that shows the parameters, compared with the one spec (ctseg/params.py): the
VTK filters' Set/Get pairs, the ParaView properties (declared through a stub of ParaView's
decorators, so no ParaView is needed), the 3D Slicer parameter node and fields (with a
stub ``slicer`` module), and the command line."""
import importlib.util
import inspect
import os
import sys
import types
from xml.dom.minidom import parseString

import pytest

import ctseg
from ctseg.errors import ParameterError
from ctseg.params import AUTO, AUTO_NUMBER, DEFAULTS, SPECS, SegmentParams
from ctseg.filters import (CTSegmentFilter, CVTSitesFilter, DelaunayMeshFilter,
                           DensityMapFilter, GraphCutSegmentFilter, MaterialBoundaryFilter,
                           MetalStreakFilter, SubpixelBoundaryFilter, TriangleGrayFilter)

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STAGE_FILTERS = (MetalStreakFilter, DensityMapFilter, CVTSitesFilter, DelaunayMeshFilter,
                 TriangleGrayFilter, GraphCutSegmentFilter, SubpixelBoundaryFilter,
                 MaterialBoundaryFilter)
PROXIES = {"CTSegment": CTSegmentFilter, "CTMetalStreaks": MetalStreakFilter,
           "CTDensityMap": DensityMapFilter, "CTCVTSites": CVTSitesFilter,
           "CTDelaunayMesh": DelaunayMeshFilter, "CTTriangleGray": TriangleGrayFilter,
           "CTGraphCut": GraphCutSegmentFilter, "CTSubpixelBoundary": SubpixelBoundaryFilter,
           "CTMaterialBoundary": MaterialBoundaryFilter}


def _group(*groups):
    return {n for n, p in SPECS.items() if p.group in groups}


# --------------------------------------------------------------------- the VTK filters
def test_each_filter_declares_its_stage_parameters():
    assert set(CTSegmentFilter.PARAMETERS) == set(SPECS)
    assert set(DensityMapFilter.PARAMETERS) == _group("density")
    assert set(CVTSitesFilter.PARAMETERS) == {
        "n_sites", "pixels_per_site", "site_rule", "boundary_px_per_site", "min_pixels_per_site",
        "density_sigma_px", "voxels_per_site", "init", "seed", "ward_block_px"} | _group("cvt")
    assert set(MetalStreakFilter.PARAMETERS) == _group("levels") | {
        "density_floor", "density_saturation", "streak_sigma_px", "streak_margin_px",
        "streak_rounds", "streak_min_explained", "streak_model", "streak_min_gain"}
    assert set(SubpixelBoundaryFilter.PARAMETERS) == {"subpixel_boundary", "subpixel_max_shift",
                                                      "gray_levels", "sliver_min_dihedral_deg"}
    assert set(GraphCutSegmentFilter.PARAMETERS) == _group("levels", "graphcut", "recursion") | {
        "density_floor", "density_saturation", "blur_correction", "blur_min_self_weight",
        "blur_max_px"}
    for cls in (DelaunayMeshFilter, TriangleGrayFilter, MaterialBoundaryFilter):
        assert cls.PARAMETERS == ()


@pytest.mark.parametrize("cls", (CTSegmentFilter,) + STAGE_FILTERS, ids=lambda c: c.__name__)
def test_filter_set_get_pairs_follow_the_spec(cls):
    f = cls()
    for name in cls.PARAMETERS:
        spec = SPECS[name]
        getter, setter = getattr(f, f"Get{spec.vtk}"), getattr(f, f"Set{spec.vtk}")
        assert getter() == spec.default == f.GetParameter(name), name
        assert spec.doc in (setter.__doc__ or ""), name
        t0 = f.GetMTime()
        setter(spec.default)
        setter(spec.to_number(spec.default))  # the same value as VTK sends it
        assert f.GetMTime() == t0, f"{name}: Modified() without a change"
        other = _other_value(spec)
        setter(other)
        assert getter() == other and f.GetMTime() > t0, name
        f.SetParameter(name, spec.default)
        assert getter() == spec.default, name
    assert f.params == DEFAULTS
    # a parameter of another stage is refused by name, not swallowed
    foreign = [n for n in SPECS if n not in cls.PARAMETERS]
    for name in foreign[:3]:
        with pytest.raises(ParameterError, match=f"{name}: not a parameter of {cls.__name__}"):
            f.SetParameter(name, SPECS[name].default)
        assert not hasattr(f, f"Set{SPECS[name].vtk}"), name


def _other_value(spec):
    """A valid value other than the default."""
    if spec.kind == "bool":
        return not spec.default
    if spec.kind == "choice":
        return next(c for c in spec.choices if c != spec.default)
    if spec.kind == "floats":
        return (10.0, 20.5)
    for candidate in (spec.high, spec.low, (spec.low + spec.high) // 2, 0.75 * spec.low + 0.25 * spec.high):
        try:
            value = spec.check(candidate)
        except ParameterError:
            continue
        if value != spec.default:
            return value
    raise AssertionError(f"{spec.name}: no other valid value found")


def test_bad_values_name_parameter_value_and_range():
    f = CTSegmentFilter()
    for name, spec in SPECS.items():
        bad = "nonsense" if spec.kind in ("choice", "bool", "floats") else spec.high * 2 + 1
        with pytest.raises(ParameterError) as err:
            getattr(f, f"Set{spec.vtk}")(bad)
        message = str(err.value)
        assert message.startswith(f"{name}: ") and repr(bad) in message, message
        assert spec.range_text() in message, message
    with pytest.raises(ParameterError, match="did you mean 'n_sites'"):
        f.SetParameter("n_site", 100)


class _Recording(SegmentParams):
    """Defaults that remember which parameters were read."""

    def __getattribute__(self, name):
        if name in SPECS:
            READ.add(name)
        return super().__getattribute__(name)


READ = set()


def test_stage_filters_take_exactly_what_their_functions_read():
    """What the ctseg function behind each stage reads from its parameters is what the
    stage filter declares; the keyword functions take the filter's names."""
    from ctseg.beam_hardening import correct_streaks
    from ctseg.labelling import label_mesh

    from ctseg.phantoms import make_phantom

    img = make_phantom(96, seed=0).image.astype(float)  # steel: the correction acts
    READ.clear()
    assert correct_streaks(img, _Recording()).weight > 0
    assert READ == set(MetalStreakFilter.PARAMETERS), READ ^ set(MetalStreakFilter.PARAMETERS)
    mesh = ctseg.delaunay_mesh(ctseg.random_sites(img.shape, 400))
    gray = ctseg.triangle_gray(img, mesh.points, mesh.triangles)
    READ.clear()
    label_mesh(img, mesh, gray, _Recording())
    assert READ == set(GraphCutSegmentFilter.PARAMETERS), READ ^ set(GraphCutSegmentFilter.PARAMETERS)
    keywords = lambda fn: set(list(inspect.signature(fn).parameters)[1:])  # noqa: E731
    assert keywords(ctseg.density_map) == set(DensityMapFilter.PARAMETERS)
    from ctseg.cvt3d import lloyd_cvt_3d

    from ctseg.site_budget import site_budget

    cvt = (keywords(ctseg.initial_sites) | keywords(ctseg.lloyd_cvt) | keywords(site_budget)
           | keywords(lloyd_cvt_3d)) - {"sites", "progress", "spacing"}
    # n_sites auto: site_budget for a slice, voxels_per_site for a volume; fine_iter_3d:
    # stages3d.cvt_sites_3d's choice between coarse_sites_3d and lloyd_cvt_3d alone
    assert cvt | {"voxels_per_site", "fine_iter_3d"} == set(CVTSitesFilter.PARAMETERS)


# ------------------------------------------------------------------------- ParaView
class _Recorder:
    """Stand-in for one of smproxy/smproperty/smdomain/smhint: every decorator records
    (decorator, kwargs) on what it decorates and returns it unchanged."""

    def __init__(self, kind):
        self.kind = kind

    def __getattr__(self, method):
        def make(*args, **kwargs):
            def decorate(obj):
                if "_stub_calls" not in vars(obj):
                    setattr(obj, "_stub_calls", [])
                obj._stub_calls.append((f"{self.kind}.{method}", args, kwargs))
                return obj
            return decorate
        return make


@pytest.fixture(scope="module")
def paraview_plugin():
    stub = types.ModuleType("paraview.util.vtkAlgorithm")
    for kind in ("smproxy", "smproperty", "smdomain", "smhint"):
        setattr(stub, kind, _Recorder(kind))
    saved = {k: sys.modules.get(k) for k in ("paraview", "paraview.util", "paraview.util.vtkAlgorithm")}
    sys.modules.update({"paraview": types.ModuleType("paraview"),
                        "paraview.util": types.ModuleType("paraview.util"),
                        "paraview.util.vtkAlgorithm": stub})
    try:
        path = os.path.join(ROOT, "plugin", "paraview", "ctseg_paraview.py")
        spec = importlib.util.spec_from_file_location("ctseg_paraview_stubbed", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        for k, v in saved.items():
            if v is None:
                sys.modules.pop(k, None)
            else:
                sys.modules[k] = v
    return module


def _calls(obj, prefix):
    return [(args, kw) for name, args, kw in vars(obj).get("_stub_calls", []) if name.startswith(prefix)]


def _property_of(setter):
    """(vector decorator, its kwargs, {domain kind: kwargs or xml}) of a decorated setter."""
    vector = [(n, kw) for n, _, kw in setter._stub_calls if n.startswith("smproperty.")]
    assert len(vector) == 1, setter._stub_calls
    domains = {}
    for n, args, kw in setter._stub_calls:
        if n in ("smdomain.intrange", "smdomain.doublerange"):
            domains["range"] = (n, kw)
        elif n == "smdomain.xml":
            node = parseString(args[0]).documentElement
            domains[node.tagName] = node
    return vector[0][0], vector[0][1], domains


def test_paraview_proxies_names_menus_ports(paraview_plugin):
    for name, base in PROXIES.items():
        cls = getattr(paraview_plugin, name)
        assert issubclass(cls, base)
        (_, proxy_kw), = _calls(cls, "smproxy.filter")
        assert proxy_kw["name"] == name and proxy_kw["label"].startswith("CT ")
        assert ((paraview_plugin.MENU,), {}) in _calls(cls, "smhint.xml")
        ports = [kw["name"] for _, kw in _calls(cls, "smproperty.input")]
        two = ("CTTriangleGray", "CTGraphCut", "CTSubpixelBoundary")
        assert ports == (["Mesh", "Image"] if name in two else ["Input"])
    outputs = [a[0] for a, _ in _calls(paraview_plugin.CTSegment, "smproperty.xml") if "OutputPort" in a[0]]
    assert len(outputs) == 2


def test_paraview_properties_are_the_spec(paraview_plugin):
    for name, base in PROXIES.items():
        cls = getattr(paraview_plugin, name)
        declared = {k for k, v in vars(cls).items() if hasattr(v, "_stub_calls") and k.startswith("Set")}
        assert declared == {f"Set{SPECS[n].vtk}" for n in base.PARAMETERS}, name
        for pname in base.PARAMETERS:
            spec = SPECS[pname]
            vector, kw, domains = _property_of(vars(cls)[f"Set{spec.vtk}"])
            assert kw["name"] == spec.vtk and kw["command"] == f"Set{spec.vtk}"
            if spec.kind == "floats":  # a text field: 'auto' or '40, 115, 150'
                assert vector == "smproperty.stringvector", pname
                assert kw["default_values"] == spec.to_text(spec.default), pname
                assert "Documentation" in domains and "range" not in domains, pname
                continue
            assert kw["default_values"] == [spec.to_number(spec.default)], pname
            want = "smproperty.doublevector" if spec.kind == "float" else "smproperty.intvector"
            assert vector == want, pname
            if spec.kind == "choice":
                entries = domains["EnumerationDomain"].getElementsByTagName("Entry")
                assert [(int(e.getAttribute("value")), e.getAttribute("text")) for e in entries] \
                    == list(enumerate(spec.choices)), pname
            elif spec.kind == "bool":
                assert "BooleanDomain" in domains, pname
            else:
                rng_kind, rng = domains["range"]
                assert rng_kind == ("smdomain.doublerange" if spec.kind == "float" else "smdomain.intrange")
                low = min(spec.low, AUTO_NUMBER) if spec.auto else spec.low
                assert (rng["min"], rng["max"]) == (low, spec.high), pname
            doc = domains["Documentation"].firstChild.data
            assert spec.doc[1:] in doc and spec.doc[:1].lower() == doc[:1].lower(), pname
            assert spec.unit in doc and (f"{AUTO_NUMBER} = automatic" in doc) == spec.auto, pname


def test_paraview_groups_follow_the_properties(paraview_plugin):
    """CTSegment's properties are grouped by stage; ParaView reads the methods'
    declarations in attribute-name order, so the groups' carrier sorts after them."""
    cls = paraview_plugin.CTSegment
    (xml,), _ = _calls(vars(cls)["_property_groups"], "smproperty.xml")[0]
    groups = parseString(f"<root>{xml}</root>").getElementsByTagName("PropertyGroup")
    members = [[p.getAttribute("name") for p in g.getElementsByTagName("Property")] for g in groups]
    assert sum(members, []) == [spec.vtk for spec in SPECS.values()]
    assert sorted(k for k, v in vars(cls).items() if hasattr(v, "_stub_calls"))[-1] == "_property_groups"


def test_paraview_setters_take_paraview_numbers(paraview_plugin):
    seg = paraview_plugin.CTSegment()
    seg.SetNumberOfSites(0)
    seg.SetInitialization(SPECS["init"].choices.index("random"))
    seg.SetBlurCorrection(0)
    seg.SetLambda(50.0)
    assert (seg.GetNumberOfSites(), seg.GetInitialization(), seg.GetBlurCorrection(),
            seg.GetLambda()) == (AUTO, "random", False, 50.0)
    dens = paraview_plugin.CTDensityMap()
    dens.SetDensityFloor(0.05)
    assert dens.params.density_floor == 0.05


# ------------------------------------------------------------------------- 3D Slicer
class _Node:
    def __init__(self, **values):
        self.values = dict(values)

    def GetParameter(self, name):
        return self.values.get(name, "")

    def SetParameter(self, name, text):
        self.values[name] = text


@pytest.fixture(scope="module")
def slicer_logic():
    saved = sys.modules.get("slicer")
    sys.modules["slicer"] = types.ModuleType("slicer")
    try:
        path = os.path.join(ROOT, "plugin", "slicer", "CTSeg", "CTSegLib", "logic.py")
        spec = importlib.util.spec_from_file_location("ctseg_slicer_logic_stubbed", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        if saved is None:
            sys.modules.pop("slicer", None)
        else:
            sys.modules["slicer"] = saved
    return module


def test_slicer_parameters_are_the_spec(slicer_logic):
    params = slicer_logic.PARAMETERS
    assert list(params) == [p.vtk for p in SPECS.values()]
    for vtk_name, spec in params.items():
        assert spec is SPECS[spec.name]
        text = slicer_logic.parameter_text(spec, spec.default)
        assert spec.parse(text) == spec.default, vtk_name
        field = slicer_logic.field_description(spec)
        assert spec.doc in field["tooltip"] and spec.range_text() in field["tooltip"]
        if spec.kind == "bool":
            assert field["widget"] == "check"
        elif spec.kind == "choice":
            assert field["widget"] == "combo" and field["items"] == list(spec.choices)
        elif spec.kind == "floats":
            assert field["widget"] == "text"
            assert spec.parse(slicer_logic.parameter_text(spec, (1.5, 20.0))) == (1.5, 20.0)
        else:
            assert field["widget"] == spec.kind
            low = min(spec.low, AUTO_NUMBER) if spec.auto else spec.low
            assert (field["minimum"], field["maximum"]) == (low, spec.high), vtk_name
            assert (field["special"] == AUTO) == spec.auto, vtk_name
            if spec.kind == "float" and spec.default != AUTO:
                assert round(spec.default, field["decimals"]) == spec.default, vtk_name


def test_slicer_node_text_read_back_with_the_spec(slicer_logic):
    logic = slicer_logic.CTSegLogic(scene=None)
    defaults = {n: slicer_logic.parameter_text(s, s.default) for n, s in slicer_logic.PARAMETERS.items()}
    assert logic.parameters(_Node(**defaults)) == DEFAULTS
    node = _Node(**{**defaults, "Lambda": "50", "NumberOfSites": "0", "SliceAxis": "y",
                    "BlurCorrection": "false"})
    p = logic.parameters(node)
    assert (p.lam, p.n_sites, p.axis, p.blur_correction) == (50.0, AUTO, "y", False)
    assert p.replace(lam=DEFAULTS.lam, axis=DEFAULTS.axis, blur_correction=True) == DEFAULTS
    with pytest.raises(ParameterError, match="Lambda: lam: 'many'"):
        logic.parameters(_Node(Lambda="many"))


# ---------------------------------------------------------------------- command line
# The contract the CLI is written to (ctseg/cli.py): named options for the parameters
# with Param.cli, --set NAME=VALUE for every parameter, `ctseg params` printing the table,
# and params_from_args(args) -> SegmentParams. Adjust here if that contract changes.
CLI_MESH = ["mesh", "in.npy", "-o", "out.vtp"]


def _cli_params(*extra):
    from ctseg.cli import build_parser, params_from_args

    return params_from_args(build_parser().parse_args(CLI_MESH + list(extra)))


def test_cli_set_and_named_options_follow_the_spec():
    assert _cli_params() == DEFAULTS
    assert _cli_params("--set", "lam=50").lam == 50.0
    for name, spec in SPECS.items():
        other = _other_value(spec)
        text = str(other).lower() if spec.kind == "bool" else spec.to_text(other)
        assert getattr(_cli_params("--set", f"{name}={text}"), name) == other, name
        if spec.cli and spec.kind == "bool":
            assert getattr(_cli_params(spec.cli), name) is (not spec.default), name
        elif spec.cli:
            assert getattr(_cli_params(spec.cli, text), name) == other, name
    with pytest.raises(ParameterError, match="lam"):
        _cli_params("--set", "lam=-1")


def test_cli_params_table_lists_every_parameter(capsys):
    from ctseg.cli import main

    assert main(["params"]) == 0
    out = capsys.readouterr().out
    for name, spec in SPECS.items():
        assert name in out and spec.range_text() in out, name
    assert all(spec.cli in out for spec in SPECS.values() if spec.cli)
