"""`bouncefit export` of a maps material (src/export/maps.rs) against the reference tools:
the Khronos glTF validator (npm gltf-validator, installed by setup.sh), MaterialX's document
validation (PyPI materialx) and Mitsuba 3 rendering the `--scene` export against
`bouncefit render` of the same capture.

The maps material is made here in the encodings of src/maps/files.rs: a 32 x 32 texel grid of
four quadrants, each its own material, so that a texture read upside down or mirrored renders a
different material: top left (row 0, +y edge; column 0, -x edge) a copper-like metal, top right
an orange dielectric, bottom left a blue dielectric with a tinted F0, bottom right a rough grey
metal whose shading normals lean towards +x and -y. The anisotropic variant stretches the
copper's roughness along x (alpha 0.3 by 0.1) and the tilted grey metal's along y (0.25 by
0.7), so a swapped axis, a tangent that does not follow the shading normal's frame or a
rotation the wrong way renders a different lobe. The Mitsuba comparison is that of
test_render_mitsuba.py (mean relative difference over the pixels wholly on the sample, all
photos and channels); `height: uncorrelated` is Mitsuba's G2.
"""

import json
import shutil
import subprocess
import time
from pathlib import Path

import cv2
import MaterialX as mx
import mitsuba as mi
import numpy as np
import pytest

from conftest import ROOT, read_exr, report, run, run_json, write_exr
from test_render_mitsuba import wholly_on_sample

TOLERANCE = 0.01
NODE = Path(__file__).resolve().parent / "node"
SIDE = 32

# (F0, diffuse albedo, alpha, tangent-space normal slopes (p, q)) per quadrant: top left, top
# right, bottom left, bottom right.
QUADRANTS = [
    ((0.95, 0.64, 0.54), (0.0, 0.0, 0.0), 0.3, (0.0, 0.0)),
    ((0.04, 0.04, 0.04), (0.6, 0.25, 0.1), 0.15, (0.0, 0.0)),
    ((0.05, 0.04, 0.03), (0.1, 0.35, 0.6), 0.5, (0.0, 0.0)),
    ((0.9, 0.9, 0.9), (0.0, 0.0, 0.0), 0.6, (-0.25, 0.15)),
]
# (alpha_x, alpha_y) per quadrant of the anisotropic variant.
ANISOTROPIC = [(0.3, 0.1), (0.15, 0.15), (0.5, 0.5), (0.25, 0.7)]


def write_png16(path, rgb):
    """Linear values in [0, 1] as a 16-bit RGB PNG (OpenCV writes BGR)."""
    codes = np.round(np.clip(rgb, 0.0, 1.0) * 65535).astype(np.uint16)
    assert cv2.imwrite(str(path), codes[..., ::-1])


@pytest.fixture(params=[False, True], ids=["isotropic", "anisotropic"])
def maps_material(request, tmp_path):
    """The four-quadrant maps material file (module docs) in tmp_path, isotropic or not."""
    anisotropic = request.param
    half = SIDE // 2
    grids = {name: np.zeros((SIDE, SIDE, 3)) for name in ("specular", "diffuse", "roughness", "normal")}
    for index, (f0, diffuse, alpha, (p, q)) in enumerate(QUADRANTS):
        rows = slice(0, half) if index < 2 else slice(half, SIDE)
        columns = slice(0, half) if index % 2 == 0 else slice(half, SIDE)
        normal = np.array([-p, -q, 1.0]) / np.linalg.norm([-p, -q, 1.0])
        ax, ay = ANISOTROPIC[index] if anisotropic else (alpha, alpha)
        for name, value in (("specular", f0), ("diffuse", diffuse), ("roughness", (ax, ay, ay)),
                            ("normal", 0.5 * normal + 0.5)):
            grids[name][rows, columns] = value
    folder = tmp_path / "quadrants.maps"
    folder.mkdir()
    for name in ("specular", "diffuse", "normal"):
        write_png16(folder / f"{name}.png", grids[name])
    write_exr(folder / "roughness.exr", grids["roughness"])
    material = {
        "model": "single", "ndf": "ggx", "height": "uncorrelated", "diffuse": [0, 0, 0],
        "maps": {"diffuse": "quadrants.maps/diffuse.png", "specular": "quadrants.maps/specular.png",
                 "roughness": "quadrants.maps/roughness.exr", "normal": "quadrants.maps/normal.png"},
    }
    path = tmp_path / "quadrants.json"
    path.write_text(json.dumps(material))
    return path


def is_anisotropic(material):
    """Whether the maps material file `material` has texels rougher along one axis."""
    roughness = read_exr(material.parent / "quadrants.maps" / "roughness.exr")
    return bool((roughness[..., 0] != roughness[..., 1]).any())


def validate_gltf(path):
    """The Khronos validator's report of the glTF file `path` and the files it names."""
    node = shutil.which("node")
    if node is None:
        pytest.fail("no node on PATH: tests/crosscheck/setup.sh installs nodejs (apt-get)")
    done = subprocess.run([node, str(NODE / "validate_gltf.js"), str(path)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def test_gltf_export_of_maps_validates(tmp_path, maps_material):
    out = tmp_path / "quadrants.gltf"
    run("export", maps_material, "--format", "gltf", "-o", out)
    result = validate_gltf(out)
    issues = result["issues"]
    codes = sorted({m["code"] for m in issues["messages"]})
    print(f"gltf-validator {result['validatorVersion']}: {issues['numErrors']} errors, "
          f"{issues['numWarnings']} warnings, {issues['numInfos']} infos, {issues['numHints']} hints {codes}")
    errors = [m for m in issues["messages"] if m["severity"] == 0]
    assert issues["numErrors"] == 0, errors
    info = result["info"]
    # base colour, metallic-roughness, specular colour (tinted dielectric F0), normal, and for
    # anisotropic maps the anisotropy texture
    anisotropic = is_anisotropic(maps_material)
    assert info["hasTextures"] and len(result["info"]["resources"]) >= 5 + anisotropic
    assert info["totalTriangleCount"] == 2 and info["drawCallCount"] == 1
    material = json.loads(out.read_text())["materials"][0]
    assert ("KHR_materials_anisotropy" in material.get("extensions", {})) == anisotropic


def test_materialx_export_of_maps_validates(tmp_path, maps_material):
    out = tmp_path / "quadrants.mtlx"
    run("export", maps_material, "--format", "materialx", "-o", out)
    document = mx.createDocument()
    mx.readFromXmlFile(document, str(out))
    library = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), library)
    document.importLibrary(library)
    valid, message = document.validate()
    assert valid, message
    images = {node.getName(): node.getInputValue("file") for node in document.getNodes("image")}
    expected = {"base_color_image", "metallic_roughness_image", "specular_color_image", "normal_image"}
    anisotropic = is_anisotropic(maps_material)
    if anisotropic:
        expected |= {"standard_surface_roughness_image", "open_pbr_roughness_image", "tangent_image"}
    assert set(images) == expected
    for file in images.values():
        assert (tmp_path / file).is_file(), file
    roughness = {
        "SR_bouncefit_standard_surface": "standard_surface_roughness" if anisotropic else "roughness",
        "SR_bouncefit_open_pbr_surface": "open_pbr_roughness" if anisotropic else "roughness",
    }
    for shader, node_name in roughness.items():
        node = document.getNode(shader)
        assert node.getNodeDef() is not None, shader
        assert node.getInput("base_color").getNodeName() == "base_color_image"
        assert node.getInput("specular_roughness").getNodeName() == node_name
    tangent = document.getNode("SR_bouncefit_open_pbr_surface").getInput("geometry_tangent")
    assert (tangent is not None and tangent.getNodeName() == "tangent_image") == anisotropic


@pytest.mark.parametrize("capture", ["copper-flash", "aluminium-pinhole"])
def test_mitsuba_export_of_maps_matches_render(tmp_path, maps_material, capture):
    folder = ROOT / "datasets" / capture
    run("export", maps_material, "--format", "mitsuba", "--scene", folder, "-o", tmp_path / "scenes")
    start = time.perf_counter()
    run("render", "--capture", folder, "--material", maps_material, "--pixel-samples", 16, "-o", tmp_path / "ours")
    ours_seconds = time.perf_counter() - start

    photos = run_json("records", folder)["photos"]
    differences = []
    for photo in photos:
        image = np.array(mi.render(mi.load_file(str(tmp_path / "scenes" / f"{photo['stem']}.xml"))), dtype=np.float64)
        ours = read_exr(tmp_path / "ours" / f"{photo['stem']}.exr")
        assert image.shape == ours.shape
        inside = wholly_on_sample(photo)
        assert inside.sum() > 0.3 * inside.size and (ours[inside] > 0).all()
        relative = np.abs(image - ours) / np.where(ours > 0, ours, 1.0)
        differences.append(relative[inside])
    values = np.concatenate(differences)
    mean = values.mean()
    report(f"{capture}: maps, bouncefit render vs Mitsuba 3 export, mean relative over wholly covered pixels",
           mean, TOLERANCE)
    print(f"  worst single value {values.max():.3e}, 99th percentile {np.percentile(values, 99):.3e}; "
          f"bouncefit render {ours_seconds:.2f} s")
    assert mean < TOLERANCE
