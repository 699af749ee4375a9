"""Static checks of the stage images (no Docker engine needed): each Dockerfile installs the extra
that covers every third-party module its stage imports, and each rule runs in its stage's image."""
import ast
import re
import sys
import tomllib
from importlib.metadata import packages_distributions
from pathlib import Path

import pytest

from testing.tiny_scene import write_scene
from testing.workflow import run_snakemake

REPO = Path(__file__).resolve().parents[2]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
FIRST_PARTY = {"schemas", "splat", "stages"}
STAGES = sorted(p.parent.name for p in (REPO / "stages").glob("*/Dockerfile"))


def imported_modules(folders: list[Path]) -> set[str]:
    """Top-level names of every module imported anywhere (lazy imports too) in these folders' .py files
    (or these .py files)."""
    names = set()
    for folder in folders:
        for path in [folder] if folder.suffix == ".py" else folder.rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.Import):
                    names |= {alias.name.split(".")[0] for alias in node.names}
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names.add(node.module.split(".")[0])
    return names - set(sys.stdlib_module_names) - FIRST_PARTY


def normalise(name: str) -> str:
    return re.sub(r"[-_.]+", "-", name).lower()


def requirement(spec: str) -> tuple[str, set[str]]:
    """'physmotion[diffusion]>=1' -> ('physmotion', {'diffusion'})."""
    m = re.match(r"\s*([A-Za-z0-9._-]+)\s*(?:\[([^\]]*)\])?", spec)
    return normalise(m.group(1)), {e.strip() for e in (m.group(2) or "").split(",") if e.strip()}


def declared_distributions(extras: set[str]) -> set[str]:
    """The distributions `pip install .[extras]` asks for: core dependencies plus the extras,
    following the project's references to its own extras."""
    wanted = {requirement(spec)[0] for spec in PYPROJECT["project"]["dependencies"]}
    todo, seen = list(extras), set()
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for spec in PYPROJECT["project"]["optional-dependencies"][extra]:
            name, sub = requirement(spec)
            if name == normalise(PYPROJECT["project"]["name"]):
                todo += sub
            else:
                wanted.add(name)
    return wanted


def missing_distributions(modules: set[str], declared: set[str]) -> dict[str, list[str]]:
    """Module -> its distributions, for each imported module that no declared distribution provides."""
    providers = packages_distributions()
    missing = {}
    for module in sorted(modules):
        dists = providers.get(module)
        if not dists:
            missing[module] = ["<not installed here, so its distribution is unknown>"]
        elif not {normalise(d) for d in dists} & declared:
            missing[module] = dists
    return missing


def dockerfile(stage: str) -> str:
    return (REPO / "stages" / stage / "Dockerfile").read_text()


def dockerfile_install(stage: str) -> tuple[set[str], set[str]]:
    """(extras of the project, other packages) that the Dockerfile's pip install lines name."""
    extras, others = set(), set()
    instructions = re.sub(r"^#.*\n", "", dockerfile(stage), flags=re.M).replace("\\\n", " ")
    for line in re.findall(r"pip install([^\n&]*)", instructions):
        words = iter(line.split())
        for word in words:
            word = word.strip("\"'")
            if word == "--index-url":
                next(words)
            if word.startswith("-"):
                continue
            m = re.fullmatch(r"\.\[([^\]]*)\]", word)
            if m:
                extras |= {e.strip() for e in m.group(1).split(",")}
            elif word != ".":
                others.add(requirement(word)[0])
    return extras, others


def stage_modules(stage: str) -> set[str]:
    return imported_modules([REPO / "schemas", REPO / "splat", REPO / "stages" / stage])


def test_every_stage_has_an_image():
    assert STAGES == ["enhance", "reconstruct", "render", "simulate"]


@pytest.mark.parametrize("stage", STAGES)
def test_dockerfile_installs_what_its_stage_imports(stage):
    extras, others = dockerfile_install(stage)
    assert extras == {stage}, f"stages/{stage}/Dockerfile should install the project's '{stage}' extra"
    missing = missing_distributions(stage_modules(stage), declared_distributions(extras) | others)
    assert not missing, f"stages/{stage} (with schemas and splat) imports modules that its image lacks: {missing}"


@pytest.mark.parametrize("stage", ["render", "simulate"])  # reconstruct's prior lgm runs ImageDream through diffusers
def test_images_without_diffusion_hold_no_diffusers(stage):
    extras, others = dockerfile_install(stage)
    assert "diffusers" not in declared_distributions(extras) | others


def test_check_catches_a_missing_extra():
    """The enhance stage without its extra lacks diffusers and peft: the check must say so."""
    missing = missing_distributions(stage_modules("enhance"), declared_distributions(set()))
    assert {"diffusers", "peft"} <= set(missing)


@pytest.mark.parametrize("stage", STAGES)
def test_image_pins_torch_and_runs_its_stage_program(stage):
    text = dockerfile(stage)
    assert "torch==2.13.0" in text and "ARG TORCH_INDEX=" in text
    program = re.search(r'ENTRYPOINT \["([\w-]+)"\]', text).group(1)
    assert PYPROJECT["project"]["scripts"][program].startswith(f"stages.{stage}.")


def rule_blocks() -> dict[str, str]:
    blocks = {}
    for smk in (REPO / "workflow" / "rules").glob("*.smk"):
        parts = re.split(r"^rule (\w+):\n", smk.read_text(), flags=re.M)
        blocks.update(dict(zip(parts[1::2], parts[2::2])))
    return blocks


def test_each_rule_runs_in_the_image_of_its_program():
    blocks = rule_blocks()
    # plots draws the report's SVGs where snakemake runs (a local rule, no image): only numpy and h5py
    assert set(blocks) == {"reconstruct", "simulate", "render", "lora", "invert", "enhance", "plots"}
    assert "container:" not in blocks.pop("plots")
    assert not imported_modules([REPO / "stages" / "setup" / "plots.py"]) - {"numpy", "h5py"}
    for rule, body in blocks.items():
        image = re.search(r'container:\s*\n\s*image\("(\w+)"\)', body)
        assert image, f"rule {rule} names no container image"
        program = re.search(r'"(pm-[\w-]+) ', body).group(1)
        module = PYPROJECT["project"]["scripts"][program]
        assert module.startswith(f"stages.{image.group(1)}."), f"rule {rule} runs {program} ({module})"


def planned_resources(workdir: Path, *config: str) -> dict[str, dict[str, str]]:
    """Rule -> resources that a dry run of the tiny scene plans."""
    write_scene(workdir / "scenes" / "tiny")
    proc = run_snakemake(workdir / "scenes", workdir / "results", "-n", config=config)
    assert proc.returncode == 0, proc.stderr[-2000:]
    plan = {}
    for rule, resources in re.findall(r"^(?:local)?rule (\w+):\n(?:.*\n)*?\s+resources: (.*)$", proc.stdout, re.M):
        plan[rule] = dict(item.split("=", 1) for item in resources.split(", "))
    return plan


def test_rules_declare_resources_for_a_scheduler(tmp_path):
    plan = planned_resources(tmp_path, "gpu=1")
    for rule in ("reconstruct", "simulate", "render", "enhance"):
        assert {"mem_mb", "runtime", "gpu"} <= set(plan[rule]), rule
    assert all(plan[rule]["gpu"] == "1" for rule in ("reconstruct", "simulate", "render"))
    assert plan["enhance"]["gpu"] == "0", "the flow backend runs on the CPU and should not hold a GPU"
    assert planned_resources(tmp_path / "laptop")["simulate"]["gpu"] == "0"
