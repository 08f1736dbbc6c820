"""The maps report of `compare --maps` on datasets/two-materials, opened in a real browser:
Debian's headless Chromium (installed by setup.sh).

- Every `<img>` of the page loads: a copy of `report.html` with a small script added records, on
  the page's load event, each image's `naturalWidth` (0 for an image that is missing or does not
  decode) in the DOM that `chromium --dump-dom` prints. A copy with one image's data corrupted
  must be caught by the same check, so the check itself is tested.
- A screenshot of the page is not blank: most of it is not one colour, and it holds the many
  colours of the maps, the relit spheres and the photos.
"""

import json
import re
import shutil
import subprocess

import cv2
import numpy as np
import pytest

FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]
WINDOW = (1280, 2400)
RECORD_IMAGES = """<script>
window.addEventListener("load", () => {
  const images = Array.from(document.images).map(i => [i.alt, i.complete ? i.naturalWidth : 0]);
  document.body.setAttribute("data-images", JSON.stringify(images));
});
</script>"""


def chromium(tmp_path, *args):
    """Runs headless Chromium with a fresh profile; returns its stdout."""
    binary = shutil.which("chromium")
    if binary is None:
        pytest.fail("no chromium on PATH: tests/crosscheck/setup.sh installs it (apt-get)")
    profile = tmp_path / f"profile-{len(list(tmp_path.glob('profile-*')))}"
    done = subprocess.run([binary, *FLAGS, f"--user-data-dir={profile}", *map(str, args)],
                          capture_output=True, text=True, timeout=180)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def loaded_images(tmp_path, html, name):
    """`(alt, naturalWidth)` of every image of the page `html`, as Chromium loads it."""
    page = tmp_path / name
    page.write_text(html.replace("</body>", RECORD_IMAGES + "</body>"))
    dom = chromium(tmp_path, "--virtual-time-budget=10000", "--dump-dom", page.as_uri())
    found = re.search(r'data-images="([^"]*)"', dom)
    assert found, "the page's load event never ran"
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))


def test_maps_report_images_load_in_chromium(tmp_path, two_materials_report):
    html = (two_materials_report / "report.html").read_text()
    images = loaded_images(tmp_path, html, "report.html")
    broken = [alt for alt, width in images if width == 0]
    print(f"{len(images)} images, {len(broken)} missing or broken")
    assert len(images) == html.count("<img ") and len(images) > 0
    assert broken == []
    # The maps are readable: three maps per row at 256 pixels or more each.
    maps = [width for alt, width in images if alt.startswith("Maps:")]
    assert maps and maps[0] >= 3 * 256, maps

    # The check catches an image whose data does not decode.
    start = html.index("data:image/png;base64,") + len("data:image/png;base64,")
    corrupted = html[:start] + "AAAA" + html[start + 4 :]
    assert [w for _, w in loaded_images(tmp_path, corrupted, "corrupted.html")].count(0) == 1


def test_maps_report_screenshot_is_not_blank(tmp_path, two_materials_report):
    shot = tmp_path / "report.png"
    chromium(tmp_path, f"--screenshot={shot}", f"--window-size={WINDOW[0]},{WINDOW[1]}",
             (two_materials_report / "report.html").as_uri())
    image = cv2.imread(str(shot))
    assert image is not None and image.shape[:2] == (WINDOW[1], WINDOW[0])
    colours, counts = np.unique(image.reshape(-1, 3), axis=0, return_counts=True)
    background = counts.max() / counts.sum()
    print(f"screenshot {shot}: {len(colours)} colours, the commonest covers {background:.1%}")
    assert background < 0.9 and len(colours) > 1000
