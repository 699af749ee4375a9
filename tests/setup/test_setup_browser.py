"""pm-setup in a real browser: Debian's chromium, headless, driven through chromedriver by selenium.

One browser session walks the whole flow a user takes on the coffee example's photograph. With
PHYSMOTION_SCREENSHOTS=1 its screenshots replace docs/setup_*.png (the README shows them).
"""
import json
import os
import shutil
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from schemas import load_scene
from stages.reconstruct.metrics import iou

from .conftest import REPO, chromium_paths, coffee_folder

pytestmark = pytest.mark.slow
if chromium_paths() is None:
    pytestmark = [pytestmark, pytest.mark.skip(reason="chromium and chromedriver are not installed (Debian: "
                                               "apt-get install chromium chromium-driver; make test does it as root)")]


@pytest.fixture
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    chromium, driver = chromium_paths()
    options = Options()
    options.binary_location = chromium
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--window-size=1500,950"):
        options.add_argument(flag)
    session = webdriver.Chrome(service=Service(driver), options=options)
    yield session
    session.quit()


def wait(browser, script: str, timeout: float = 60):
    """Poll a JavaScript expression until it is truthy; its value."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        value = browser.execute_script(f"return {script}")
        if value:
            return value
        time.sleep(0.2)
    page = browser.execute_script("return [document.getElementById('status').textContent, "
                                  "[...document.querySelectorAll('.error-msg, .error')].map(e => e.textContent)]")
    raise AssertionError(f"timed out waiting for {script}; the page says {page}")


def masks_ready(browser, timeout=60):
    wait(browser, "window.pm && pm.scene && pm.pendingMasks === 0 && pm.masks.length > 0 && pm.masks[0] !== undefined",
         timeout)


def drag(browser, points, tool=None):
    """Press at the first photograph pixel, move through the others, release at the last."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    if tool:
        browser.find_element(By.CSS_SELECTOR, f'[data-tool="{tool}"]').click()
    canvas = browser.find_element(By.ID, "canvas")
    scale, width, height = browser.execute_script("return [pm.scale, pm.canvas.width, pm.canvas.height]")
    offset = lambda p: (round(p[0] * scale - width / 2), round(p[1] * scale - height / 2))  # from the centre
    chain = ActionChains(browser).move_to_element_with_offset(canvas, *offset(points[0])).click_and_hold()
    for p in points[1:]:
        chain = chain.move_to_element_with_offset(canvas, *offset(p))
    chain.release().perform()


def screenshot(browser, tmp_path: Path, name: str):
    path = tmp_path / name
    browser.save_screenshot(str(path))
    if os.environ.get("PHYSMOTION_SCREENSHOTS"):
        shutil.copyfile(path, REPO / "docs" / name)


def test_set_up_save_reload_and_preview_a_scene(tmp_path, start_server, browser):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    folder = coffee_folder(tmp_path)
    server = start_server(folder, "--image", str(folder / "coffee.png"))
    browser.get(server.url + "/")
    masks_ready(browser)

    # a box around the cup: the mask at once, GrabCut's as pm-reconstruct computes it
    drag(browser, [(96, 0), (200, 120), (280, 210)], tool="box")
    wait(browser, "pm.pendingMasks === 0 && pm.scene.objects[0].box")
    masks_ready(browser)
    box = browser.execute_script("return pm.scene.objects[0].box")
    assert box == pytest.approx([96, 0, 280, 210], abs=2)
    boxed = browser.execute_script("return pm.masks[0].pixels")
    truth = cv2.imread(str(REPO / "scenes" / "coffee" / "mask.png"), 0) > 127

    # GrabCut alone keeps only the cup's pale rim (red cup on a red saucer): object strokes down its body
    # bring the rest, a background stroke on the spoon takes that out again
    drag(browser, [(130, 110), (160, 160), (200, 178), (245, 150), (255, 110)], tool="fg")
    wait(browser, f"pm.pendingMasks === 0 && pm.masks[0].pixels > {boxed}")
    grown = browser.execute_script("return pm.masks[0].pixels")
    drag(browser, [(222, 182), (236, 188), (250, 192)], tool="bg")
    wait(browser, f"pm.pendingMasks === 0 && pm.masks[0].pixels < {grown}")
    stroked = browser.execute_script("return pm.masks[0].pixels")
    under = browser.execute_script(
        "const d = pm.masks[0].canvas.getContext('2d').getImageData(236, 188, 1, 1).data; return d[3]")
    assert under == 0
    screenshot(browser, tmp_path, "setup_mask.png")

    # a preset: the metal keys appear, from the models' schema
    Select(browser.find_element(By.ID, "preset")).select_by_value("metal")
    assert browser.find_elements(By.NAME, "objects[0].material.yield_stress")

    # an impulse, its arrow dragged up and to the right
    Select(browser.find_element(By.ID, "condition-type")).select_by_value("impulse")
    browser.find_element(By.ID, "add-condition").click()
    tip = browser.execute_script("return Draw.handles(pm, 0).find(h => h.kind === 'vector').at")
    centre = browser.execute_script("return Draw.regionGeometry(pm, pm.scene.physics.conditions[0]).centre")
    target = (centre[0] + 60, centre[1] - 45)
    drag(browser, [tip, ((tip[0] + target[0]) / 2, (tip[1] + target[1]) / 2), target], tool="move")
    velocity = browser.execute_script("return pm.scene.physics.conditions[0].velocity")
    per_unit = browser.execute_script("return Draw.pixelsPerUnit(pm, pm.scene.physics.conditions[0])")
    assert velocity[:2] == pytest.approx([60 / per_unit, -45 / per_unit], rel=0.08)

    # the cup's foot held: a fixed region as a box, its corners dragged to the object's lower fifth
    Select(browser.find_element(By.ID, "condition-type")).select_by_value("fixed")
    browser.find_element(By.ID, "add-condition").click()
    Select(browser.find_element(By.NAME, "physics.conditions[1].region")).select_by_value("box")
    x0, y0, x1, y1 = browser.execute_script("return Draw.objectRect(pm, 0)")
    for corner, target in (("corner1", (x1, y1)), ("corner0", (x0, y0 + 0.8 * (y1 - y0)))):
        at = browser.execute_script(f"return Draw.handles(pm, 1).find(h => h.kind === '{corner}').at")
        drag(browser, [at, target], tool="move")
    region = browser.execute_script("return pm.scene.physics.conditions[1].region.box")
    assert region[:2] == pytest.approx([0, 0.8], abs=0.02) and region[3:5] == pytest.approx([1, 1], abs=0.01)
    browser.execute_script("document.querySelector('.condition').scrollIntoView()")
    screenshot(browser, tmp_path, "setup_conditions.png")

    # save: scene.yaml the loader accepts, with the hint image
    browser.find_element(By.ID, "save").click()
    wait(browser, "document.getElementById('status').textContent.startsWith('saved')")
    scene = load_scene(folder)
    assert scene.objects[0].material.preset == "metal" and list(scene.objects[0].box) == box
    assert list(scene.physics.conditions[0].velocity) == velocity
    assert scene.physics.conditions[1].type == "fixed" and list(scene.physics.conditions[1].region.box) == region
    hints = cv2.imread(str(scene.objects[0].hints), cv2.IMREAD_UNCHANGED)
    assert hints[188, 236, 3] == 255 and hints[188, 236, :3].max() == 0  # background: opaque black
    assert hints[160, 160, 3] == 255 and hints[160, 160, :3].min() == 255  # object: opaque white
    saved_state = browser.execute_script("return JSON.stringify(pm.scene)")

    # reload: the same scene, the same mask
    browser.refresh()
    masks_ready(browser)
    assert json.loads(browser.execute_script("return JSON.stringify(pm.scene)")) == json.loads(saved_state)
    assert browser.execute_script("return pm.masks[0].pixels") == stroked
    mask = browser.execute_script("return pm.masks[0].canvas.toDataURL()")
    page_mask = cv2.imdecode(np.frombuffer(__import__("base64").b64decode(mask.split(",")[1]), np.uint8),
                             cv2.IMREAD_UNCHANGED)[..., 3] > 0
    assert iou(page_mask, truth) > 0.8  # the example's hand-painted mask (GrabCut alone: 0.62)

    # the saved scene's preview
    started = time.time()
    browser.find_element(By.ID, "preview").click()
    wait(browser, "document.getElementById('preview-pane').dataset.state === 'running'", 20)
    screenshot(browser, tmp_path, "setup_progress.png")
    state = wait(browser, "['done', 'failed'].includes(document.getElementById('preview-pane').dataset.state) && "
                 "document.getElementById('preview-pane').dataset.state", 150)
    assert state == "done", browser.find_element(By.ID, "preview-msg").text
    frames = int(browser.execute_script("return document.getElementById('preview-pane').dataset.frames"))
    assert frames == round(scene.physics.duration_s * 8) + 1
    wait(browser, "document.getElementById('preview-frame').naturalWidth > 0", 10)
    time.sleep(1.0)
    screenshot(browser, tmp_path, "setup_preview.png")
    print(f"preview in the browser: {time.time() - started:.1f} s")
