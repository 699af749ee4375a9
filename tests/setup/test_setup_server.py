"""pm-setup's server as a local program: what it serves, what it refuses, what it writes."""
import base64
import http.client
import json
import shutil
import socket
import time
from urllib.parse import urlparse

import cv2
import numpy as np
import pytest
import yaml

from schemas import load_scene
from stages.reconstruct.segment import ObjectSpec, SamSegmenter, read_photo, segment_objects
from stages.setup.scene_file import MAX_IMAGE_BYTES

from ..reconstruct.test_reconstruct_models import tiny_sam  # noqa: F401 (a fixture)
from .conftest import REPO, coffee_folder


def request(server, method: str, path: str, body=None, raw: bytes | None = None):
    """(status, parsed JSON or bytes); the path goes out exactly as given (no '..' folding by a client)."""
    url = urlparse(server.url)
    conn = http.client.HTTPConnection(url.hostname, url.port, timeout=120)
    data = raw if raw is not None else (json.dumps(body).encode() if body is not None else None)
    conn.request(method, path, body=data, headers={"Content-Type": "application/json"} if body is not None else {})
    response = conn.getresponse()
    payload = response.read()
    conn.close()
    try:
        return response.status, json.loads(payload)
    except ValueError:
        return response.status, payload


def data_url(image: np.ndarray) -> str:
    return "data:image/png;base64," + base64.b64encode(cv2.imencode(".png", image)[1].tobytes()).decode()


@pytest.fixture
def ball(tmp_path, start_server):
    folder = tmp_path / "ball"
    shutil.copytree(REPO / "scenes" / "ball", folder)
    (tmp_path / "secret.txt").write_text("outside the scene folder")
    return folder, start_server(folder)


@pytest.mark.parametrize("path", ["/files/../secret.txt", "/files/%2e%2e/secret.txt", "/files/..%2fsecret.txt",
                                  "/files//etc/passwd", "/files/%2fetc%2fpasswd", "/files/" + "/etc/passwd",
                                  "/files/./../secret.txt", "/static/../scene_file.py", "/static/%2e%2e%2fserver.py",
                                  "/preview/../secret.txt", "/files/link/secret.txt"])
def test_only_the_scene_folder_and_the_page_are_served(ball, path):
    folder, server = ball
    (folder / "link").symlink_to(folder.parent)  # a link out of the folder is no way out either
    status, payload = request(server, "GET", path)
    assert status == 404, (path, payload)
    assert request(server, "GET", "/files/photo.png")[0] == 200
    assert request(server, "GET", "/static/app.js")[0] == 200


def test_listens_on_loopback_only(ball):
    _, server = ball
    port = urlparse(server.url).port
    assert urlparse(server.url).hostname == "127.0.0.1"
    probe = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        probe.connect(("10.255.255.255", 1))  # no packet is sent: this only picks the outward interface
        outward = probe.getsockname()[0]
    except OSError:
        outward = None
    finally:
        probe.close()
    if outward is None or outward.startswith("127."):
        pytest.skip("this machine has no address besides loopback to try")
    with pytest.raises(OSError):
        socket.create_connection((outward, port), timeout=2)


def test_uploads_are_limited_and_checked(ball):
    folder, server = ball
    status, payload = request(server, "POST", "/api/photo?name=big.png", raw=b"\x89PNG\r\n\x1a\n" + bytes(MAX_IMAGE_BYTES))
    assert status == 413 and "limit" in payload["error"]["message"]
    status, payload = request(server, "POST", "/api/photo?name=fake.png", raw=b"<html>not an image</html>")
    assert status == 400 and "not a PNG or JPEG" in payload["error"]["message"]
    status, payload = request(server, "POST", "/api/photo?name=cut.png", raw=(folder / "photo.png").read_bytes()[:200])
    assert status == 400 and "cannot be decoded" in payload["error"]["message"]
    status, _ = request(server, "POST", "/api/photo?name=../../escape.png", raw=(folder / "photo.png").read_bytes())
    assert status == 200 and (folder / "escape.png").is_file() and not (folder.parent.parent / "escape.png").exists()
    assert not any(folder.glob(".*partial*")) and not (folder / "big.png").exists() and not (folder / "fake.png").exists()


def test_saving_what_was_opened_keeps_every_key_and_the_comments(ball):
    folder, server = ball
    before = load_scene(folder)
    comments = [line for line in (folder / "scene.yaml").read_text().splitlines() if line.startswith("#")]
    status, state = request(server, "GET", "/api/scene")
    assert status == 200 and state["error"] is None
    state["scene"]["enhance"]["relight"] = False  # one edit to a key the page has no special control for
    status, saved = request(server, "PUT", "/api/scene", {"scene": state["scene"], "hints": {}})
    assert status == 200, saved
    after = load_scene(folder)
    expected = before.model_dump()
    expected["enhance"]["relight"] = False
    assert after.model_dump() == expected
    text = (folder / "scene.yaml").read_text()
    assert text.splitlines()[: len(comments)] == comments and "velocity: [0.0, -1.2, 0.0]" in text


def test_a_refused_key_is_named_and_nothing_is_written(ball):
    folder, server = ball
    original = (folder / "scene.yaml").read_bytes()
    _, state = request(server, "GET", "/api/scene")
    state["scene"]["objects"][0]["material"]["poisson_ratio"] = 0.7
    status, payload = request(server, "PUT", "/api/scene", {"scene": state["scene"], "hints": {}})
    assert status == 422
    assert payload["error"]["field"] == "objects[0].material.poisson_ratio"
    assert "less than 0.5" in payload["error"]["message"]
    assert (folder / "scene.yaml").read_bytes() == original and not any(folder.glob(".*"))
    status, payload = request(server, "POST", "/api/check", {"scene": state["scene"]})
    assert payload["error"]["field"] == "objects[0].material.poisson_ratio"


def test_the_saved_hints_give_pm_reconstruct_the_mask_the_page_showed(tmp_path, start_server):
    folder = coffee_folder(tmp_path)
    server = start_server(folder, "--image", str(folder / "coffee.png"))
    box = [96, 0, 280, 210]  # the cup and its saucer's near rim
    _, plain = request(server, "POST", "/api/mask", {"object": 0, "box": box})
    strokes = np.zeros((256, 384, 4), np.uint8)
    cv2.line(strokes, (110, 150), (270, 200), (50, 50, 255, 255), 9)  # the page paints background red (BGR)
    status, hinted = request(server, "POST", "/api/mask", {"object": 0, "box": box, "hints": data_url(strokes)})
    assert status == 200 and hinted["pixels"] < plain["pixels"]
    page_mask = cv2.imdecode(np.frombuffer(base64.b64decode(hinted["mask"].split(",")[1]), np.uint8), 0) > 127
    assert not (page_mask & (strokes[..., 3] > 0)).any()
    _, state = request(server, "GET", "/api/scene")
    state["scene"]["objects"][0].update(box=box, size_m=0.09)
    status, saved = request(server, "PUT", "/api/scene", {"scene": state["scene"], "hints": {"0": data_url(strokes)}})
    assert status == 200, saved
    scene = load_scene(folder)
    assert scene.objects[0].hints == folder / "hints_0.png"
    photo, alpha = read_photo(scene.image)
    labels = segment_objects(photo, alpha, [ObjectSpec(box=tuple(box), hints=scene.objects[0].hints)])
    assert np.array_equal(labels > 0, page_mask)


def wait_for(server, states, timeout=120):
    deadline = time.time() + timeout
    while time.time() < deadline:
        _, status = request(server, "GET", "/api/preview")
        if status["state"] in states:
            return status
        time.sleep(0.3)
    raise AssertionError(f"preview still {status}")


def test_preview_cancel_stops_the_stage(ball):
    folder, server = ball
    status, started = request(server, "POST", "/api/preview")
    assert status == 200 and started["state"] == "running"
    time.sleep(1.0)
    request(server, "DELETE", "/api/preview")
    finished = wait_for(server, ("cancelled", "done", "failed"), timeout=30)
    assert finished["state"] == "cancelled" and finished["done_stages"] == 0


def test_a_stage_error_reaches_the_page_as_the_stages_paragraph(tmp_path, start_server):
    folder = coffee_folder(tmp_path)
    # the table's corner: GrabCut finds no object there, which only pm-reconstruct can tell
    (folder / "scene.yaml").write_text(yaml.safe_dump({"image": "coffee.png", "objects": [{"box": [330, 200, 384, 256]}]}))
    server = start_server(folder)
    request(server, "POST", "/api/preview")
    finished = wait_for(server, ("cancelled", "done", "failed"), timeout=90)
    assert finished["state"] == "failed"
    assert finished["message"].startswith("pm-reconstruct: error in") and "objects[0].box" in finished["message"]


def test_with_a_local_sam_model_the_box_is_refined_by_sam(ball, tiny_sam):
    """As pm-reconstruct does it: a box without hints goes to SAM when the scene names a local model."""
    folder, server = ball
    _, state = request(server, "GET", "/api/scene")
    state["scene"]["reconstruct"] = {"sam_model": str(tiny_sam)}
    status, _ = request(server, "PUT", "/api/scene", {"scene": state["scene"], "hints": {}})
    assert status == 200
    box = [90, 70, 230, 210]
    status, answer = request(server, "POST", "/api/mask", {"object": 0, "box": box})
    assert status == 200 and answer["method"] == "SAM in the box"
    photo, alpha = read_photo(folder / "photo.png")
    expected = segment_objects(photo, alpha, [ObjectSpec(box=tuple(box))], sam=SamSegmenter(tiny_sam)) > 0
    page_mask = cv2.imdecode(np.frombuffer(base64.b64decode(answer["mask"].split(",")[1]), np.uint8), 0) > 127
    assert np.array_equal(page_mask, expected)
