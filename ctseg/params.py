"""Every parameter of ctseg, once: its type, default, valid range, unit and meaning.

The parameters are grouped by stage in frozen dataclasses nested in
:class:`SegmentParams`. Everything else is derived from this module, never retyped: the
keyword defaults of the stage functions, :func:`ctseg.segment_image`'s keywords, the
``ctseg`` command's options and ``--set name=value``, ``ctseg params``, the VTK filters'
Set/Get pairs, the ParaView properties, the 3D Slicer parameter node, the ``--report``
and the key that lets a volume run resume.

Names are unique across groups, so a parameter is addressed by its name alone
(``SegmentParams().lam``, ``segment_image(img, lam=50)``). One sentinel, :data:`AUTO`
(the string ``'auto'``), means "derived from the data" wherever a parameter allows it;
``None`` is read as AUTO at the public entries. Where a layer can only hold numbers (a
VTK property, a spin box) AUTO is written as 0, which no automatic parameter admits as a
value of its own.

Example
-------
>>> p = SegmentParams().replace(lam=50.0)
>>> p.lam, p.graphcut.beta
(50.0, 0.286)
>>> SegmentParams.from_dict(p.to_dict()) == p
True
"""
import dataclasses
import difflib
import json
from dataclasses import dataclass, field

from ._param import AUTO, AUTO_NUMBER, Param, _Group, _param
from .errors import ParameterError

__all__ = ["AUTO", "AUTO_NUMBER", "Param", "SegmentParams", "SPECS", "DEFAULTS", "check",
           "resolve", "resolve_name", "table"]


@dataclass(frozen=True)
class DensityParams(_Group):
    """The gradient density map (SPEC 1): where the CVT puts its sites."""

    group = "density"
    density_sigma_px: float = _param(1.0, "float", "Gaussian pre-smoothing of the density "
                                     "map", "px", low=0.0, high=10.0, vtk="DensitySigma")
    density_floor: float = _param(0.02, "float", "density added everywhere so that flat "
                                  "regions keep sites", low=0.0, high=1.0, low_open=True)
    density_saturation: float = _param(AUTO, "float", "gradient that gets the full density, as a fraction of "
                                       "the largest; 1 = the paper's normalisation; auto = from the noise",
                                       low=0.0, high=1.0, low_open=True, auto=True)
    density_ridge: float = _param(2.0, "float", "ridge sharpening exponent (0 = the paper's map)", low=0.0, high=8.0)
    density_small_boost: float = _param(1.0, "float", "slices: density times this on small closed features' "
                                        "edges (at most 16 px across: a pin, a pore) and 2 px around; 1 = off",
                                        low=1.0, high=100.0)


@dataclass(frozen=True)
class SiteParams(_Group):
    """The initial sites (SPEC 2): how many and how they are placed."""

    group = "sites"
    n_sites: int = _param(AUTO, "int", "CVT sites (mesh vertices) per slice; auto = from "
                          "the slice's size and boundary length (site_rule)", low=4,
                          high=100_000_000, auto=True, vtk="NumberOfSites", cli="--sites")
    pixels_per_site: float = _param(128.0, "float", "pixels per site when n_sites is auto: "
                                    "the least a slice gets (at least 16 sites, at most one "
                                    "per pixel)", "px", low=1.0, high=1e6)
    site_rule: str = _param("boundary", "choice", "auto n_sites: sites boundary_px_per_site "
                            "px apart along the boundaries but at least one per pixels_per_site "
                            "pixels (voxels_per_site in 3D), or that minimum only (the old "
                            "rule)", choices=("boundary", "area"))
    boundary_px_per_site: float = _param(3.0, "float", "pixels of boundary length per site "
                                         "when n_sites is auto (site_rule boundary)", "px",
                                         low=0.5, high=1e6)
    min_pixels_per_site: float = _param(8.0, "float", "the boundary rule gives at most one "
                                        "site per this many pixels", "px", low=1.0, high=1e6)
    init: str = _param("ward", "choice", "initial sites: Ward's clustering (the paper's), "
                       "uniform random, or random by density",
                       choices=("ward", "random", "density_random"), vtk="Initialization")
    seed: int = _param(0, "int", "seed of the random initialisations", low=0,
                       high=2 ** 31 - 1, cli="--seed")
    voxels_per_site: float = _param(180.0, "float", "3D mode, n_sites auto: the least a volume "
                                    "gets, one site per this many voxels (at least 64)",
                                    "voxels", low=1.0, high=1e9)
    ward_block_px: int = _param(AUTO, "int", "Ward pre-merge block side (1 = exact Ward; in "
                                "3D along the finest axis); auto = about 16 blocks per site", "px", low=1, high=1024,
                                auto=True, vtk="WardBlockPixels")


@dataclass(frozen=True)
class CVTParams(_Group):
    """Lloyd's iterations of the pixel CVT (SPEC 3)."""

    group = "cvt"
    tol_px: float = _param(0.01, "float", "Lloyd stops when no site moves more than this (in 3D: times the "
                           "smallest spacing)", "px", low=0.0, high=10.0, low_open=True, vtk="Tolerance")
    max_iter: int = _param(200, "int", "Lloyd iteration cap", low=1, high=100_000,
                           vtk="MaximumIterations")
    energy_rtol_3d: float = _param(0.0, "float", "the 3D Lloyd also stops when an iteration lowers the CVT "
                                   "energy by less than this share of it (0 = off: only tol_px and max_iter)",
                                   low=0.0, high=1.0, vtk="EnergyTolerance3D")
    overrelaxation_3d: float = _param(1.0, "float", "the 3D Lloyd moves a free site this many times the way to "
                                      "its centroid (1 = Lloyd's step; below 2 the energy still never increases)",
                                      low=1.0, high=2.0, high_open=True, vtk="OverRelaxation3D")
    fine_iter_3d: int = _param(10, "int", "the 3D Lloyd runs first on 2 x 2 x 2 voxel blocks, then at most this "
                               "many iterations on the voxels (0 = on the voxels only, to max_iter)",
                               low=0, high=100_000, vtk="FineIterations3D")


@dataclass(frozen=True)
class TetraParams(_Group):
    """The tetrahedra of the 3D mode (SPEC 9.4): slivers perturbed away for FE use."""

    group = "tetrahedra"
    sliver_min_dihedral_deg: float = _param(5.0, "float", "tetrahedra with a smaller "
                                            "dihedral angle are slivers: their vertices "
                                            "are moved a little and the sites "
                                            "triangulated again", "deg", low=0.0, high=30.0,
                                            vtk="SliverMinDihedral")
    sliver_rounds: int = _param(40, "int", "rounds of sliver perturbation (0 = none)",
                                low=0, high=1000)


@dataclass(frozen=True)
class LevelParams(_Group):
    """The material gray levels: the gray map onto 0-255 and the modes of the flat pixels
    (SPEC conventions and 7)."""

    group = "levels"
    n_materials: int = _param(AUTO, "int", "exact number of materials; auto = found from the "
                              "data", low=1, high=64, auto=True, vtk="NumberOfMaterials",
                              cli="--materials")
    gray_levels: tuple = _param(AUTO, "floats", "the materials' gray levels, one per "
                                "material, lowest first (material k is the k-th); auto = "
                                "found from the data", "input gray", auto=True, cli="--levels")
    rescale_low_pct: float = _param(0.5, "float", "percentile mapped to gray 0 of the 0-255 "
                                    "scale", "%", low=0.0, high=50.0, high_open=True)
    rescale_high_pct: float = _param(99.5, "float", "percentile mapped to gray 255", "%",
                                     low=50.0, high=100.0, low_open=True)
    flat_sigma_px: float = _param(1.0, "float", "smoothing of the gradient that tells flat "
                                  "pixels (which measure the levels) from edges", "px",
                                  low=0.0, high=10.0)
    merge_k: float = _param(5.0, "float", "levels closer than merge_k noise sd (+ merge_rel x "
                            "gray) are one material", "noise sd", low=0.0, high=100.0)
    merge_rel: float = _param(0.2, "float", "gray-proportional part of the level separation "
                              "(beam hardening grows with attenuation)", low=0.0, high=10.0)
    merge_floor_255: float = _param(2.0, "float", "smallest level separation", "gray 0-255",
                                    low=0.0, high=255.0, low_open=True)
    merge_threshold_255: float = _param(AUTO, "float", "fixed level separation instead of "
                                        "the rule above; auto = the rule", "gray 0-255",
                                        low=0.0, high=255.0, low_open=True, auto=True)
    level_min_fraction: float = _param(1e-3, "float", "share of the flat pixels a level must "
                                       "hold", low=0.0, high=1.0, high_open=True)


@dataclass(frozen=True)
class GraphCutParams(_Group):
    """The binary graph cut of an element graph (SPEC 6, the paper's eqs. 6-9)."""

    group = "graphcut"
    lam: float = _param(70.0, "float", "weight of the neighbour terms (the paper's lambda)",
                        low=0.0, high=1e6, vtk="Lambda")
    beta: float = _param(0.286, "float", "weight of the distance term of the neighbour "
                         "capacities (the paper's beta)", low=0.0, high=100.0)
    eps_255: float = _param(1.0, "float", "added to neighbour gray differences so that equal "
                            "neighbours get a finite capacity", "gray 0-255", low=0.0,
                            high=255.0, low_open=True)
    theta_255: float = _param(AUTO, "float", "seed-set width; auto = 10% of the component's "
                              "gray range", "gray 0-255", low=0.0, high=255.0, low_open=True,
                              auto=True)
    weight_by_edge_length: bool = _param(False, "bool", "multiply neighbour capacities by the shared "
                                         "edge length, in 3D face area (px / voxel units; not the paper's)")


@dataclass(frozen=True)
class RecursionParams(_Group):
    """The recursive cut and the rules that turn its leaves into materials (SPEC 7)."""

    group = "recursion"
    step_threshold_255: float = _param(AUTO, "float", "gray step above which an element "
                                       "straddles a boundary; auto = 4 x the step noise, at "
                                       "least 2", "gray 0-255", low=0.0, high=255.0,
                                       low_open=True, auto=True)
    min_triangles: int = _param(2, "int", "components smaller than this are not split",
                                low=1, high=1_000_000)
    max_depth: int = _param(32, "int", "recursion depth cap of the graph cuts", low=0,
                            high=1000)
    min_material_area: float = _param(AUTO, "float", "interior area a gray mode needs to be a "
                                      "material; auto = max(16, 0.1% of the image)", "px^2",
                                      low=0.0, high=1e12, low_open=True, auto=True)
    min_pocket_area: float = _param(4.0, "float", "interior area of a material that makes a "
                                    "component worth splitting", "px^2", low=0.0, high=1e12)


@dataclass(frozen=True)
class CorrectionParams(_Group):
    """Corrections beyond the paper: metal streaks before, edge blur after the first
    labelling, boundary vertices at the ISO-50 crossing at the end."""

    group = "corrections"
    streak_correction: bool = _param(True, "bool", "first remove the dark beam-hardening "
                                     "streaks next to metal", cli="--no-streak-correction")
    streak_sigma_px: float = _param(1.0, "float", "smoothing before pixels are classified for "
                                    "the streak fit", "px", low=0.0, high=10.0,
                                    vtk="StreakSigma")
    streak_margin_px: int = _param(3, "int", "pixels this close to the metal are left out of "
                                   "the streak fit", "px", low=0, high=100, vtk="StreakMargin")
    streak_rounds: int = _param(3, "int", "rounds of streak fit and re-classification",
                                low=1, high=20)
    streak_min_explained: float = _param(0.05, "float", "a streak correction that removes "
                                         "less of the within-material variance is not "
                                         "applied", low=0.0, high=1.0)
    streak_model: str = _param("halo", "choice", "streak model: metal path length L squared; "
                               "polynomial: also L^3 and L times the other materials' path; "
                               "halo: also a glow around the metal", choices=("square",
                               "polynomial", "halo"), vtk="StreakModel")
    streak_min_gain: float = _param(0.2, "float", "polynomial model only where it removes this "
                                    "share of what the square one leaves", low=0.0, high=1.0)
    blur_correction: bool = _param(True, "bool", "take off the edge blur the first labelling "
                                   "predicts and label again", cli="--no-blur-correction")
    blur_min_self_weight: float = _param(0.8, "float", "floor of a triangle's self weight in "
                                         "the blur correction (1 = no amplification)",
                                         low=0.0, high=1.0, low_open=True)
    blur_max_px: float = _param(3.0, "float", "largest point-spread sd the blur fit "
                                "considers", "px", low=0.0, high=20.0, low_open=True,
                                vtk="BlurMax")
    subpixel_boundary: bool = _param(True, "bool", "move each vertex between two materials "
                                     "to where the gray crosses the mean of their levels "
                                     "(ISO-50), within the mesh (SPEC 10)",
                                     cli="--no-subpixel-boundary")
    subpixel_max_shift: float = _param(0.5, "float", "largest such move, as a share of the "
                                       "vertex's shortest edge", low=0.0, high=1.0,
                                       low_open=True, high_open=True)


@dataclass(frozen=True)
class VolumeParams(_Group):
    """How a volume is meshed, and where the work happens (n_jobs never changes the
    result)."""

    group = "volume"
    mode: str = _param("auto", "choice", "how a volume is meshed: in 3D (tetrahedra, closed surfaces), slice by "
                       "slice (triangles), or auto: 3D where the memory allows it, else slices", choices=(
                           "auto", "slices", "3d"), vtk="Mode", cli="--mode")
    axis: str = _param("z", "choice", "slice axis of a volume in slices mode",
                       choices=("z", "y", "x"), vtk="SliceAxis", cli="--axis")
    n_jobs: int = _param(AUTO, "int", "worker processes for a volume's slices (1 = this "
                         "process); auto = one per core", low=1, high=4096, auto=True,
                         vtk="NumberOfJobs", cli="--jobs")


GROUPS = (DensityParams, SiteParams, CVTParams, TetraParams, LevelParams, GraphCutParams,
          RecursionParams, CorrectionParams, VolumeParams)
RUN_ONLY = ("n_jobs",)  # never change the result: left out of the resume key

ALIASES = {  # earlier keyword names, kept so that existing calls keep working
    "sigma": ("density_sigma_px", "flat_sigma_px", "streak_sigma_px"),
    "step_threshold": ("step_threshold_255",),
    "merge_floor": ("merge_floor_255",),
    "merge_threshold": ("merge_threshold_255",),
    "theta": ("theta_255",),
}


@dataclass(frozen=True)
class SegmentParams:
    """All parameters of a segmentation, by stage.

    Attributes are the stage groups (``density``, ``sites``, ``cvt``, ``tetrahedra``,
    ``levels``, ``graphcut``, ``recursion``, ``corrections``, ``volume``); each parameter is also an
    attribute of its own name (``params.lam``). Instances are immutable and checked on
    construction: :meth:`replace` makes a changed copy.

    Example
    -------
    >>> p = SegmentParams.from_dict({"lam": 40, "n_sites": "auto"})
    >>> p.lam, p.n_sites
    (40.0, 'auto')
    """

    density: DensityParams = field(default_factory=DensityParams)
    sites: SiteParams = field(default_factory=SiteParams)
    cvt: CVTParams = field(default_factory=CVTParams)
    tetrahedra: TetraParams = field(default_factory=TetraParams)
    levels: LevelParams = field(default_factory=LevelParams)
    graphcut: GraphCutParams = field(default_factory=GraphCutParams)
    recursion: RecursionParams = field(default_factory=RecursionParams)
    corrections: CorrectionParams = field(default_factory=CorrectionParams)
    volume: VolumeParams = field(default_factory=VolumeParams)

    def __post_init__(self):
        lv = self.levels
        if lv.gray_levels != AUTO and lv.n_materials != AUTO and \
                len(lv.gray_levels) != lv.n_materials:
            raise ParameterError(f"gray_levels: {len(lv.gray_levels)} levels given "
                                 f"({SPECS['gray_levels'].to_text(lv.gray_levels)}) but n_materials="
                                 f"{lv.n_materials}; give one of them, or as many levels as "
                                 f"materials")

    def __getattr__(self, name):
        # only reached for names that are not groups: a parameter by its own name
        where = _WHERE.get(name)
        if where is None:
            raise AttributeError(name)
        return getattr(object.__getattribute__(self, where), name)

    @staticmethod
    def specs():
        """Every :class:`Param`, by name, in table order."""
        return dict(SPECS)

    def flat(self):
        """{name: value} of every parameter."""
        return {name: getattr(self, name) for name in SPECS}

    def replace(self, **overrides):
        """A copy with some parameters changed (by name; old names accepted), checked."""
        changes = {}
        for key, value in overrides.items():
            for name in resolve_name(key):
                changes.setdefault(_WHERE[name], {})[name] = value
        groups = {g: dataclasses.replace(getattr(self, g), **c) for g, c in changes.items()}
        return dataclasses.replace(self, **groups)

    def to_dict(self):
        """Nested {group: {name: value}}, JSON-ready (AUTO stays 'auto')."""
        return {cls.group: {f.name: getattr(getattr(self, cls.group), f.name)
                            for f in dataclasses.fields(cls)} for cls in GROUPS}

    @classmethod
    def from_dict(cls, data):
        """From :meth:`to_dict`'s nested form or a flat {name: value}; unknown names raise
        ParameterError naming the closest valid one."""
        flat = {}
        for key, value in dict(data).items():
            if key in _GROUP_NAMES and isinstance(value, dict):
                for name, v in value.items():
                    if _WHERE.get(name) != key:
                        resolve_name(name)  # raises for an unknown name
                        raise ParameterError(f"{name}: belongs to group "
                                             f"{_WHERE[name]!r}, not {key!r}")
                    flat[name] = v
            else:
                flat[key] = value
        return cls().replace(**flat)

    def result_key(self):
        """Canonical JSON of every parameter that can change the result (the resume key)."""
        d = self.to_dict()
        for name in RUN_ONLY:
            d[_WHERE[name]].pop(name)
        return json.dumps(d, sort_keys=True)


SPECS = {}
_WHERE = {}
for _cls in GROUPS:
    for _f in dataclasses.fields(_cls):
        SPECS[_f.name] = _cls.spec(_f.name)
        _WHERE[_f.name] = _cls.group
_GROUP_NAMES = {cls.group for cls in GROUPS}
del _cls, _f

DEFAULTS = SegmentParams()
"""The defaults, as one object: stage functions take their keyword defaults from here."""


def resolve_name(key):
    """The parameter name(s) a keyword stands for (an old name can stand for several), or
    ParameterError naming the closest valid name."""
    if key in SPECS:
        return (key,)
    if key in ALIASES:
        return ALIASES[key]
    close = difflib.get_close_matches(key, list(SPECS) + list(ALIASES), n=1, cutoff=0.5)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    raise ParameterError(f"{key}: not a ctseg parameter{hint} (`ctseg params` lists them all)")


def check(name, value):
    """``value`` checked against the spec of parameter ``name`` (ParameterError if not)."""
    return SPECS[name].check(value)


def resolve(params=None, **overrides):
    """A :class:`SegmentParams` from an optional base (a SegmentParams or a dict) and
    keyword overrides; every value checked."""
    if params is None:
        base = DEFAULTS
    elif isinstance(params, SegmentParams):
        base = params
    elif isinstance(params, dict):
        base = SegmentParams.from_dict(params)
    else:
        raise ParameterError(f"params: expected a ctseg.params.SegmentParams or a dict, got "
                             f"{type(params).__name__}")
    return base.replace(**overrides) if overrides else base


def table():
    """Rows (name, group, default, valid range, unit, doc) of every parameter."""
    return [(p.name, p.group, p.default, p.range_text(), p.unit, p.doc) for p in SPECS.values()]
