"""ParaView plugin for ctseg: the composite segmentation filter and the stage filters of
``ctseg.filters`` in the Filters menu, category "ctseg".

Load it with Tools > Manage Plugins > Load New... (this file), or put this folder on
PV_PLUGIN_PATH. ParaView's Python must be able to import ctseg and its dependencies (see
the README's ParaView section). This file only declares the ParaView proxies: every filter
is a ``ctseg.filters`` class, and every property is generated from the parameter spec
(:mod:`ctseg.params`): its name (``Param.vtk``), default, range or choices, and
documentation. A parameter that may be derived from the data takes 0 for "automatic"; a
choice is an index into its choices. In ``paraview.simple`` the filters are CTSegment,
CTMetalStreaks, CTDensityMap, CTCVTSites, CTDelaunayMesh, CTTriangleGray, CTGraphCut and
CTMaterialBoundary.
"""
from xml.sax.saxutils import escape, quoteattr

from paraview.util.vtkAlgorithm import smdomain, smhint, smproperty, smproxy

from ctseg.params import AUTO_NUMBER, SPECS
from ctseg.filters import (CTSegmentFilter, CVTSitesFilter, DelaunayMeshFilter,
                           DensityMapFilter, GraphCutSegmentFilter, MaterialBoundaryFilter,
                           MetalStreakFilter, SubpixelBoundaryFilter, TriangleGrayFilter)

MENU = '<ShowInMenu category="ctseg"/>'
GROUP_LABELS = {"density": "Density map", "sites": "Initial sites", "cvt": "CVT (Lloyd)",
                "levels": "Material levels", "graphcut": "Graph cut",
                "recursion": "Recursive cut", "corrections": "Corrections",
                "volume": "Volume"}
GROUPED_OVER = 8
"""Proxies with more properties than this show them in groups, by stage."""


def documentation(spec):
    """The property's documentation: the spec's meaning, unit and what 0 means."""
    text = spec.doc[:1].upper() + spec.doc[1:]
    if spec.unit:
        text += f" ({spec.unit})"
    if spec.auto:
        text += f"; {AUTO_NUMBER} = automatic"
    return text + "."


def number_range(spec):
    """(min, max) of a number property: the spec's bounds, with the AUTO number admitted
    where the parameter may be automatic."""
    low = spec.low
    if spec.auto:
        low = min(low, AUTO_NUMBER)
    return low, spec.high


def _enumeration(choices):
    entries = "".join(f"<Entry value=\"{k}\" text={quoteattr(str(c))}/>"
                      for k, c in enumerate(choices))
    return f'<EnumerationDomain name="enum">{entries}</EnumerationDomain>'


def _property(base, name):
    """The ParaView setter of spec parameter ``name``: the base filter's Set<Vtk> (which
    takes VTK numbers), decorated with the property, its domain and documentation."""
    spec = SPECS[name]
    base_setter = getattr(base, f"Set{spec.vtk}")

    def setter(self, value):
        base_setter(self, value)

    setter.__name__ = setter.__qualname__ = f"Set{spec.vtk}"
    setter.__doc__ = base_setter.__doc__
    default = [spec.to_number(spec.default)]
    func = smdomain.xml(f"<Documentation>{escape(documentation(spec))}</Documentation>")(setter)
    if spec.kind == "floats":  # a list of numbers, or 'auto': a text field
        return smproperty.stringvector(name=spec.vtk, command=f"Set{spec.vtk}",
                                       number_of_elements=1,
                                       default_values=spec.to_text(spec.default))(func)
    if spec.kind == "float":
        low, high = number_range(spec)
        func = smdomain.doublerange(min=low, max=high)(func)
        vector = smproperty.doublevector
    else:
        if spec.kind == "choice":
            func = smdomain.xml(_enumeration(spec.choices))(func)
        elif spec.kind == "bool":
            func = smdomain.xml('<BooleanDomain name="bool"/>')(func)
        else:
            low, high = number_range(spec)
            func = smdomain.intrange(min=int(low), max=int(high))(func)
        vector = smproperty.intvector
    return vector(name=spec.vtk, command=f"Set{spec.vtk}", number_of_elements=1,
                  default_values=default)(func)


def _groups(names):
    """PropertyGroup declarations that show the properties by stage, in the spec's order."""
    out = []
    for group in dict.fromkeys(SPECS[n].group for n in names):
        members = [SPECS[n].vtk for n in names if SPECS[n].group == group]
        props = "".join(f'<Property name="{m}"/>' for m in members)
        label = quoteattr(GROUP_LABELS.get(group, group.capitalize()))
        out.append(f"<PropertyGroup label={label}>{props}</PropertyGroup>")
    return out


def _gray_values(image_port):
    """The "Gray Values" property: the image's point array read as the gray values, sent to
    VTK's SetInputArrayToProcess (``ctseg.filters`` read it as array 0; the default is the
    image's active scalars)."""
    def carrier(self):
        """Carries the property's declaration; ParaView calls SetInputArrayToProcess."""

    carrier.__name__ = carrier.__qualname__ = "GrayValues"
    doc = escape("The image's point array read as the gray values (default: its active scalars).")
    return smproperty.xml(
        '<StringVectorProperty name="GrayValues" label="Gray Values" '
        'command="SetInputArrayToProcess" number_of_elements="5" element_types="0 0 0 0 2" '
        f'animateable="0"><ArrayListDomain name="array_list" attribute_type="Scalars" '
        f'input_domain_name="gray_values_array">'
        f'<RequiredProperties><Property name="{image_port}" function="Input"/>'
        f'</RequiredProperties></ArrayListDomain><Documentation>{doc}</Documentation>'
        '</StringVectorProperty>')(carrier)


def proxy(base, name, label, doc, inputs=(("Input", 0, "vtkImageData"),), outputs=()):
    """A ParaView filter proxy over ctseg filter class ``base``: its spec parameters as
    properties, its inputs as (port name, port index, data type) in port order, its
    output ports as (name, index), in the ctseg menu."""
    namespace = {"__module__": __name__, "__doc__": doc}
    for pname in base.PARAMETERS:
        setter = _property(base, pname)
        namespace[setter.__name__] = setter
    if len(base.PARAMETERS) > GROUPED_OVER:
        # ParaView writes the methods' declarations sorted by attribute name: this one
        # sorts after every Set..., so the groups follow the properties they name
        def property_groups(self):
            """Carries the PropertyGroup declarations; never called."""

        namespace["_property_groups"] = smproperty.xml("".join(_groups(base.PARAMETERS)))(
            property_groups)
    images = [port_name for port_name, _, data_type in inputs if data_type == "vtkImageData"]
    if images:  # ParaView writes declarations sorted by name: GrayValues before the Set...
        namespace["GrayValues"] = _gray_values(images[0])
    cls = type(name, (base,), namespace)
    for port_name, index in outputs:
        cls = smproperty.xml(f'<OutputPort name="{port_name}" index="{index}"/>')(cls)
    for port_name, index, data_type in inputs:
        cls = smdomain.datatype(dataTypes=[data_type], composite_data_supported=False)(cls)
        if port_name in images[:1]:  # the arrays Gray Values offers: the image's point arrays
            cls = smdomain.xml('<InputArrayDomain name="gray_values_array" '
                               'attribute_type="point" number_of_components="1"/>')(cls)
        cls = smproperty.input(name=port_name, port_index=index)(cls)
    return smproxy.filter(name=name, label=label)(smhint.xml(MENU)(cls))


MESH_AND_IMAGE = (("Mesh", 0, "vtkPolyData"), ("Image", 1, "vtkImageData"))

CTSegment = proxy(
    CTSegmentFilter, "CTSegment", "CT Segment",
    "CT slice or volume -> mesh with one material per element (Yang et al. 2014). Mode "
    "'slices': triangles, a volume slice by slice with one material numbering (output 1 "
    "the boundaries as polylines); Mode '3d': tetrahedra, a vtkUnstructuredGrid (output 1 "
    "the interface triangles between materials); Mode 'auto' (the default): 3D where the memory "
    "allows it, else slices.",
    outputs=(("Mesh", 0), ("Boundaries", 1)))
CTMetalStreaks = proxy(
    MetalStreakFilter, "CTMetalStreaks", "CT Metal Streaks",
    "First stage (not in the paper): the slice with the beam-hardening streaks of its "
    "densest material removed; the input values kept as an 'original' point array.")
CTDensityMap = proxy(
    DensityMapFilter, "CTDensityMap", "CT Density Map",
    "Stage 1: the gradient density map of a slice, as a 'density' point array.")
CTCVTSites = proxy(
    CVTSitesFilter, "CTCVTSites", "CT CVT Sites",
    "Stages 2-3: Ward-initialised CVT of a density map; the sites as vertices.")
CTDelaunayMesh = proxy(
    DelaunayMeshFilter, "CTDelaunayMesh", "CT Delaunay Mesh",
    "Stage 4: the Delaunay triangles of the CVT sites.",
    inputs=(("Input", 0, "vtkPolyData"),))
CTTriangleGray = proxy(
    TriangleGrayFilter, "CTTriangleGray", "CT Triangle Gray",
    "Stage 5: exact area-weighted mean gray of every triangle over the image.",
    inputs=MESH_AND_IMAGE)
CTGraphCut = proxy(
    GraphCutSegmentFilter, "CTGraphCut", "CT Graph Cut",
    "Stages 6-7: recursive graph cut of the triangles into materials.",
    inputs=MESH_AND_IMAGE)
CTSubpixelBoundary = proxy(
    SubpixelBoundaryFilter, "CTSubpixelBoundary", "CT Subpixel Boundary",
    "The labelled triangles' (tetrahedra's) boundary vertices moved to the ISO-50 crossing of the gray.",
    inputs=MESH_AND_IMAGE)
CTMaterialBoundary = proxy(
    MaterialBoundaryFilter, "CTMaterialBoundary", "CT Material Boundary",
    "The edges between materials as polylines with the materials each side.",
    inputs=(("Input", 0, "vtkPolyData"),))
