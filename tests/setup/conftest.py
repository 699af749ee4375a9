"""pm-setup servers started as a user starts them (the pm-setup program), and the headless chromium."""
import re
import shutil
import subprocess
import time
from pathlib import Path

import pytest

from testing.workflow import BIN, REPO


class Server:
    def __init__(self, folder: Path, *args: str):
        self.process = subprocess.Popen([str(BIN / "pm-setup"), str(folder), "--port", "0", *args],
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        lines = []
        deadline = time.time() + 60
        while time.time() < deadline:
            line = self.process.stdout.readline()
            lines.append(line)
            found = re.search(r"open (http://\S+)/", line)
            if found:
                self.url = found.group(1)
                return
            if not line and self.process.poll() is not None:
                break
        self.stop()
        raise RuntimeError("pm-setup did not start: " + "".join(lines))

    def stop(self):
        if self.process.poll() is None:
            self.process.terminate()
            self.process.wait(20)


@pytest.fixture
def start_server():
    servers = []

    def start(folder: Path, *args: str) -> Server:
        servers.append(Server(folder, *args))
        return servers[-1]

    yield start
    for server in servers:
        server.stop()


def coffee_folder(tmp: Path) -> Path:
    """A new scene folder holding only the coffee example's photograph (no scene.yaml, no mask)."""
    folder = tmp / "cup"
    folder.mkdir()
    shutil.copyfile(REPO / "scenes" / "coffee" / "photo.png", folder / "coffee.png")
    return folder


def chromium_paths() -> tuple[str, str] | None:
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    return (browser, driver) if browser and driver else None
