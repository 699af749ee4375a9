"""The stage images for the Docker tests: built with containers/build_images.sh (Docker's cache makes
a rebuild of unchanged code quick) and run on a mounted working folder as the calling user.
`why_unavailable` says why they cannot be built and run here, or None."""
import os
import shlex
import shutil
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
OPT_IN = "PHYSMOTION_TEST_IMAGES"
BASE = os.environ.get("BASE", "physmotion/base:bookworm")


def docker(*args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run(["docker", *args], capture_output=True, text=True, timeout=timeout)


def why_unavailable() -> str | None:
    """None when the images can be built and run here, else why not."""
    if os.environ.get(OPT_IN) != "1":
        return (f"opt-in: set {OPT_IN}=1 to build the four stage images (about 11 minutes on 2 cores whenever "
                "the code or README changed, Docker's cache otherwise) and run seven containers (about 7 minutes); "
                "TORCH_WHEEL=path takes torch from a local wheel, BASE=image names the base image")
    if not shutil.which("docker"):
        return "no docker command"
    info = docker("info", timeout=60)
    if info.returncode != 0:
        return f"`docker info` failed (no Docker engine running?): {(info.stderr or info.stdout).strip()[-300:]}"
    if BASE.startswith("physmotion/base:") and docker("image", "inspect", BASE).returncode != 0:
        if os.geteuid() != 0:
            return f"no base image {BASE}, and containers/make_base_image.sh needs root (debootstrap, chroot)"
        if not shutil.which("debootstrap"):
            proc = subprocess.run(["apt-get", "install", "-y", "-qq", "debootstrap"], capture_output=True, text=True,
                                  env={**os.environ, "DEBIAN_FRONTEND": "noninteractive"})
            if proc.returncode != 0:
                return f"no base image {BASE}, and debootstrap cannot be installed: {proc.stderr.strip()[-300:]}"
    return None


def build_images() -> None:
    """Builds (or finds in Docker's cache) physmotion/{reconstruct,simulate,render,enhance} from this tree."""
    proc = subprocess.run(["sh", str(REPO / "containers" / "build_images.sh")], capture_output=True, text=True,
                          timeout=3600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]


def run_in_image(image: str, workdir: Path, commands: list[list[str]]) -> subprocess.CompletedProcess:
    """The commands, one after another, in one container of `image` with `workdir` mounted as /work
    and no network (a stage never downloads)."""
    script = " && ".join(shlex.join(cmd) for cmd in commands)
    return docker("run", "--rm", "--network", "none", "--user", f"{os.getuid()}:{os.getgid()}", "-e", "HOME=/tmp",
                  "-v", f"{workdir}:/work", "--entrypoint", "sh", image, "-c", script, timeout=1200)
