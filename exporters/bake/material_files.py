"""The material files of ``--target openpbr``: a MaterialX document and a USD layer that read the OpenPBR maps.

* ``S_openpbr.mtlx`` — MaterialX 1.39: one ``open_pbr_surface`` (the standard library's OpenPBR Surface 1.1 node)
  whose base and subsurface inputs read the maps through ``image`` nodes in a node graph, and a
  ``surfacematerial``; checked by MaterialX's own validator against the standard data libraries before it is
  published.
* ``S_openpbr.usda`` — a UsdShade Material with two surface outputs: ``outputs:mtlx:surface`` from the same
  OpenPBR Surface as MaterialX shader nodes (``ND_open_pbr_surface_surfaceshader``, ``ND_image_*``), and the
  universal ``outputs:surface`` from a UsdPreviewSurface that shows the painted colour (``diffuseColor``), for
  renderers without MaterialX; written and re-opened with usd-core.

Both name the maps by paths relative to their own folder (``./S_openpbr_base_color.exr``), so the folder can move;
a UDIM set names them with the ``<UDIM>`` token (MaterialX and USD resolve it per tile).  The libraries are
imported here only, when a bake asks for the target (:func:`require`): the rest of the exporters, and the add-on,
run without them.  Hand-written: nothing, except the wiring; MaterialX writes, reads and validates the document,
usd-core the layer.
"""

from __future__ import annotations

import os
import re
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

from .. import image_input, maps, openpbr
from .options import BakeOptions
from .targets import BakeError, MapSpec

#: The pinned versions (pyproject.toml's ``openpbr`` extra), named in the one-line error when they are missing.
PACKAGES = "materialx==1.39.5 usd-core==26.11"
#: Specular roughness of the written material (OpenPBR's and Blender's perceptual roughness, GGX alpha = r^2):
#: facial skin's rms facet slope m = 0.4 (Weyrich et al. 2006, as blender_addon.nodes.SKIN_FACET_SLOPE), r = sqrt m.
SPECULAR_ROUGHNESS: float = 0.4**0.5
#: The OpenPBR input each map kind feeds (exporters.bake.targets' openpbr kinds), and its MaterialX type.
INPUTS: dict[str, tuple[str, str]] = {
    "openpbr_base_color": ("base_color", "color3"),
    "openpbr_subsurface_color": ("subsurface_color", "color3"),
    "openpbr_subsurface_radius": ("subsurface_radius", "float"),
    "openpbr_subsurface_radius_scale": ("subsurface_radius_scale", "color3"),
    "openpbr_subsurface_anisotropy": ("subsurface_scatter_anisotropy", "float"),
    "openpbr_subsurface_weight": ("subsurface_weight", "float"),
    "openpbr_coat_color": ("coat_color", "color3"),
}
#: Colour inputs read as linear Rec.709 (the maps are linear); the other maps are data (no colour transform).
COLOR_KINDS = frozenset({"openpbr_base_color", "openpbr_subsurface_color", "openpbr_coat_color"})
SHADER_ID = "ND_open_pbr_surface_surfaceshader"


@dataclass(frozen=True)
class MaterialFiles:
    """The two files of a material: ``mtlx`` and ``usda`` names in the output folder."""

    mtlx: str
    usda: str


def material_names(stem: str) -> MaterialFiles:
    """File names of the material of the maps with stem ``stem`` (a UDIM set's stem without its token)."""
    return MaterialFiles(mtlx=f"{stem}_openpbr.mtlx", usda=f"{stem}_openpbr.usda")


def udim_tile_options(options: BakeOptions, pattern: str | os.PathLike, last: bool) -> BakeOptions:
    """The options of one tile of the UDIM albedo ``pattern`` (``skin.<UDIM>.png``): with ``--target openpbr`` only
    the ``last`` tile writes the material, ``skin_openpbr.mtlx`` / ``.usda``, reading every tile's maps through
    ``skin.<UDIM>_openpbr_*.exr``; the other tiles write maps only.  Without the target: ``options`` unchanged."""
    if "openpbr" not in options.targets:
        return options
    set_stem = Path(Path(pattern).name).stem  # skin.<UDIM>
    material_stem = set_stem.replace(f".{image_input.UDIM_TOKEN}", "").replace(image_input.UDIM_TOKEN, "") or "udim"
    return replace(options, write_material=last, material_stem=material_stem, material_maps_stem=set_stem)


def require() -> tuple:
    """(MaterialX, pxr's Usd, UsdShade, Sdf, Tf, UsdGeom) or BakeError in one line saying what to install."""
    try:
        import MaterialX
        from pxr import Sdf, Tf, Usd, UsdGeom, UsdShade
    except ImportError as exc:
        raise BakeError(f"--target openpbr writes MaterialX and USD files and needs the materialx and usd-core "
                        f"packages, which this Python lacks ({exc.name}): pip install {PACKAGES} (in Blender, bake "
                        "the other targets here and run bake.py with the project's Python for openpbr)") from None
    return MaterialX, Usd, UsdShade, Sdf, Tf, UsdGeom


def _identifier(text: str) -> str:
    """A MaterialX element / USD prim name made of ``text`` (letters, digits, underscores; not starting with a
    digit)."""
    name = re.sub(r"\W", "_", text)
    return name if name and not name[0].isdigit() else f"_{name}"


def _map_files(specs: list[MapSpec], map_stem: str | None) -> dict[str, str]:
    """kind -> relative file name, each openpbr map once (``map_stem`` replaces the specs' stem: a UDIM set)."""
    out = {}
    for spec in specs:
        if spec.kind in INPUTS:
            name = spec.name
            if map_stem is not None:
                name = f"{map_stem}_{spec.kind}.exr"
            out[spec.kind] = name
    missing = sorted(set(INPUTS) - set(out))
    if missing:
        raise ValueError(f"the openpbr material needs the maps {missing}")
    return out


@contextmanager
def _temp_beside(path: Path, writer_creates: bool = False) -> Iterator[Path]:
    """A new hidden temporary file beside ``path`` (same suffix), removed when the block fails; kept otherwise (the
    bake moves it into place).  ``writer_creates``: the name only, for writers that create the file themselves."""
    stem, suffix = os.path.splitext(path.name)
    fd, name = tempfile.mkstemp(prefix=f".{stem}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    if writer_creates:
        tmp.unlink()
    try:
        yield tmp
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def coat_values(ior: float, roughness: float) -> dict[str, float]:
    """The constant inputs of the OpenPBR Surface: the specular layer, and over it the clear coat of the same IOR and
    roughness that carries the ``coat_color`` map (exporters.openpbr step 2: the coat's reflection is the skin's
    specular; the base, at the relative IOR 1 under it, reflects none).  ``coat_darkening`` 0: OpenPBR's darkening
    of the base by light reflected back inside the coat is not the mixture's (which the coat colour alone
    reproduces), and Blender's Principled BSDF has none."""
    return {"specular_ior": float(ior), "specular_roughness": float(roughness), "coat_weight": 1.0,
            "coat_ior": float(ior), "coat_roughness": float(roughness), "coat_darkening": 0.0}


def mtlx_document(mx, files: dict[str, str], name: str, ior: float, roughness: float):
    """The MaterialX document (not yet written) of the maps ``files`` (kind -> relative path)."""
    doc = mx.createDocument()
    doc.setColorSpace("lin_rec709")
    graph = doc.addNodeGraph(f"NG_{name}_maps")
    shader = doc.addNode("open_pbr_surface", f"{name}_openpbr", "surfaceshader")
    for kind, (input_name, mtype) in INPUTS.items():
        image = graph.addNode("image", f"{input_name}_image", mtype)
        file_input = image.setInputValue("file", files[kind], "filename")
        if kind in COLOR_KINDS:
            file_input.setColorSpace("lin_rec709")
        else:
            file_input.setColorSpace("raw")
        output = graph.addOutput(f"{input_name}_out", mtype)
        output.setConnectedNode(image)
        shader_input = shader.addInput(input_name, mtype)
        shader_input.setConnectedOutput(output)
    for input_name, value in coat_values(ior, roughness).items():
        shader.setInputValue(input_name, value)
    doc.addMaterialNode(name, shader)
    return doc


def check_mtlx(mx, doc) -> None:
    """RuntimeError unless ``doc`` is valid by MaterialX's validator with the standard data libraries."""
    library = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), library)
    doc.setDataLibrary(library)
    try:
        ok, message = doc.validate()
        shaders = [n for n in doc.getNodes() if n.getCategory() == "open_pbr_surface"]
        if not shaders or shaders[0].getNodeDef() is None:
            ok, message = False, f"no node definition for open_pbr_surface in MaterialX {mx.getVersionString()}"
    finally:
        doc.setDataLibrary(None)
    if not ok:
        raise RuntimeError(f"MaterialX rejects the OpenPBR document: {message.strip()}")


def write_mtlx(path: Path, files: dict[str, str], name: str, ior: float, roughness: float) -> Path:
    """Write the validated MaterialX document to a temporary file beside ``path``; returns that file."""
    mx = require()[0]
    doc = mtlx_document(mx, files, name, ior, roughness)
    check_mtlx(mx, doc)
    with _temp_beside(path) as tmp:
        mx.writeToXmlFile(doc, str(tmp))
    return tmp


def write_usda(path: Path, files: dict[str, str], name: str, ior: float, roughness: float,
               unit_scale_m: float) -> Path:
    """Write the USD layer to a temporary ``.usda`` beside ``path`` and re-open it to check it; returns that file."""
    require()  # one line naming the missing package, before any file is made
    with _temp_beside(path, writer_creates=True) as tmp:  # usd-core creates the layer itself
        _usd_material(tmp, files, name, ior, roughness, unit_scale_m)
        check_usda(tmp, name)
    return tmp


def _usd_material(tmp: Path, files: dict[str, str], name: str, ior: float, roughness: float,
                  unit_scale_m: float) -> None:
    """Create the layer at ``tmp``: /<name> (the default prim) holding the material /<name>/Skin."""
    _, Usd, UsdShade, Sdf, _, UsdGeom = require()
    stage = Usd.Stage.CreateNew(str(tmp))
    UsdGeom.SetStageMetersPerUnit(stage, float(unit_scale_m))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)  # Blender's
    root = UsdGeom.Scope.Define(stage, f"/{name}")
    stage.SetDefaultPrim(root.GetPrim())
    material = UsdShade.Material.Define(stage, f"/{name}/Skin")
    base = material.GetPath()
    openpbr_shader = UsdShade.Shader.Define(stage, base.AppendChild("OpenPBR"))
    openpbr_shader.CreateIdAttr(SHADER_ID)
    graph = UsdShade.NodeGraph.Define(stage, base.AppendChild("OpenPBRMaps"))
    value_type = {"color3": Sdf.ValueTypeNames.Color3f, "float": Sdf.ValueTypeNames.Float}
    for kind, (input_name, mtype) in INPUTS.items():
        image = UsdShade.Shader.Define(stage, graph.GetPath().AppendChild(input_name))
        image.CreateIdAttr(f"ND_image_{mtype}")
        file_input = image.CreateInput("file", Sdf.ValueTypeNames.Asset)
        file_input.Set(Sdf.AssetPath(f"./{files[kind]}"))
        file_input.GetAttr().SetColorSpace("lin_rec709" if kind in COLOR_KINDS else "raw")
        out = image.CreateOutput("out", value_type[mtype])
        graph_out = graph.CreateOutput(input_name, value_type[mtype])
        graph_out.ConnectToSource(out)
        openpbr_shader.CreateInput(input_name, value_type[mtype]).ConnectToSource(graph_out)
    for input_name, value in coat_values(ior, roughness).items():
        openpbr_shader.CreateInput(input_name, Sdf.ValueTypeNames.Float).Set(value)
    surface = openpbr_shader.CreateOutput("out", Sdf.ValueTypeNames.Token)
    material.CreateSurfaceOutput("mtlx").ConnectToSource(surface)
    _preview_surface(stage, UsdShade, Sdf, material, files["openpbr_base_color"], ior, roughness)
    stage.GetRootLayer().Save()


def _preview_surface(stage, UsdShade, Sdf, material, base_color: str, ior: float, roughness: float) -> None:
    """The fallback: UsdPreviewSurface with the painted colour as its diffuse colour (a texture on primvar st)."""
    base = material.GetPath()
    preview = UsdShade.Shader.Define(stage, base.AppendChild("PreviewSurface"))
    preview.CreateIdAttr("UsdPreviewSurface")
    reader = UsdShade.Shader.Define(stage, base.AppendChild("PreviewST"))
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    texture = UsdShade.Shader.Define(stage, base.AppendChild("PreviewBaseColor"))
    texture.CreateIdAttr("UsdUVTexture")
    texture.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(f"./{base_color}"))
    texture.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
    texture.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(
        reader.CreateOutput("result", Sdf.ValueTypeNames.Float2))
    rgb = texture.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    preview.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(rgb)
    preview.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(roughness))
    preview.CreateInput("ior", Sdf.ValueTypeNames.Float).Set(float(ior))
    preview.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(0)
    material.CreateSurfaceOutput().ConnectToSource(preview.CreateOutput("surface", Sdf.ValueTypeNames.Token))


def check_usda(path: Path, name: str) -> None:
    """RuntimeError unless the layer at ``path`` opens and its material's two surface outputs reach an OpenPBR
    Surface and a UsdPreviewSurface."""
    _, Usd, UsdShade, *_ = require()
    stage = Usd.Stage.Open(str(path))
    if stage is None:
        raise RuntimeError(f"usd-core cannot open {path}")
    material = UsdShade.Material(stage.GetPrimAtPath(f"/{name}/Skin"))
    if not material:
        raise RuntimeError(f"{path}: no material /{name}/Skin")
    for context, shader_id in (("mtlx", SHADER_ID), ("", "UsdPreviewSurface")):
        source = material.ComputeSurfaceSource(context)[0]
        if not source or source.GetIdAttr().Get() != shader_id:
            raise RuntimeError(f"{path}: the material's {context or 'universal'} surface is not {shader_id}")


def write_material(out_dir: Path, specs: list[MapSpec], stem: str, unit_scale_m: float, overwrite: bool,
                   ior: float = openpbr.SPECULAR_IOR, roughness: float = SPECULAR_ROUGHNESS,
                   map_stem: str | None = None) -> list[Path]:
    """Write ``<stem>_openpbr.mtlx`` and ``.usda`` for the openpbr maps of ``specs`` in ``out_dir`` (both or neither;
    an existing file is FileExistsError unless ``overwrite``); ``map_stem``: the maps' stem when it differs
    from the specs' (a UDIM set, e.g. ``skin.<UDIM>``).  Returns the two paths."""
    names = material_names(stem)
    files = _map_files(specs, map_stem)
    name = _identifier(stem)
    paths = [out_dir / names.mtlx, out_dir / names.usda]
    for p in paths:
        if p.exists() and not overwrite:
            raise FileExistsError(f"{p} exists; pass overwrite=True (--overwrite) to replace it")
    temps: list[Path] = []
    try:
        temps.append(write_mtlx(paths[0], files, name, ior, roughness))
        temps.append(write_usda(paths[1], files, name, ior, roughness, unit_scale_m))
        published: list[Path] = []
        try:
            for tmp, final in zip(temps, paths, strict=True):
                maps.publish_file(tmp, final, overwrite)
                published.append(final)
        except BaseException:
            if not overwrite:
                for p in published:
                    p.unlink(missing_ok=True)
            raise
    finally:
        for tmp in temps:
            tmp.unlink(missing_ok=True)
    return paths
