"""Fuzzing the scene loader: any document either loads or is refused with InputError, quickly.

Four sources of documents: random YAML trees, random text and bytes, and random mutations (a value
replaced, a key dropped or added, characters changed) of the example scenes, loaded beside
their own photographs and masks so that the file checks run too.
"""
import json
import shutil
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from schemas import InputError, Scene, load_scene

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = sorted((REPO / "scenes").glob("*/scene.yaml"))
PER_CASE_MS = 2000
"""A bounded time per document: every example scene loads in well under a tenth of it."""

FUZZ = settings(max_examples=150, deadline=PER_CASE_MS, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])

scalars = (st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats(allow_nan=True, allow_infinity=True)
           | st.text(max_size=20) | st.sampled_from(["all", "jelly", "sand", "impulse", "force", "photo.png",
                                                     "mask.png", "flow", "diffusion", "friction", ""]))
KEYS = st.sampled_from(["image", "objects", "physics", "camera", "render", "enhance", "reconstruct", "material",
                        "preset", "conditions", "type", "region", "box", "sphere", "velocity", "size_m", "mask",
                        "fps", "duration_s", "grid", "youngs_modulus", "ground", "object"]) | st.text(max_size=8)
trees = st.recursive(scalars, lambda children: st.lists(children, max_size=4)
                     | st.dictionaries(KEYS, children, max_size=5), max_leaves=25)


def load(folder: Path, text: str | bytes) -> None:
    """Load ``text`` as the scene.yaml of ``folder``: a Scene, or an InputError; anything else fails the test."""
    (folder / "scene.yaml").write_bytes(text if isinstance(text, bytes) else text.encode())
    try:
        assert isinstance(load_scene(folder / "scene.yaml"), Scene)
    except InputError as err:
        assert err.paragraph().startswith("error in ") and "Fix: " in err.paragraph()


@pytest.fixture
def example_folder(tmp_path) -> Path:
    """A copy of every example's images in one folder, so that mutated scenes find their files."""
    for scene in EXAMPLES:
        for image in scene.parent.glob("*.png"):
            shutil.copy(image, tmp_path / image.name)
    return tmp_path


@FUZZ
@given(tree=trees)
def test_random_yaml_trees_load_or_raise_input_error(example_folder, tree):
    load(example_folder, yaml.safe_dump(tree, allow_unicode=True))


@FUZZ
@given(text=st.text(max_size=300))
def test_random_text_loads_or_raises_input_error(example_folder, text):
    load(example_folder, text)


@FUZZ
@given(data=st.binary(max_size=200))
def test_random_bytes_load_or_raise_input_error(example_folder, data):
    load(example_folder, data)


@settings(FUZZ, max_examples=40)
@given(depth=st.integers(1, 1200), key=KEYS, opener=st.sampled_from(["[", "{a: "]))
def test_deeply_nested_documents_load_or_raise_input_error(example_folder, depth, key, opener):
    """Past a few hundred levels PyYAML's recursive composer runs out of stack (a RecursionError)."""
    closer = "]" if opener == "[" else "}"
    load(example_folder, f"image: photo.png\n{json.dumps(key)}: {opener * depth}1{closer * depth}\n")


def _paths(tree, prefix=()):
    """Every (path, value) of a YAML tree, the root first."""
    yield prefix, tree
    items = tree.items() if isinstance(tree, dict) else enumerate(tree) if isinstance(tree, list) else ()
    for key, value in items:
        yield from _paths(value, prefix + (key,))


@st.composite
def mutated_examples(draw):
    """An example scene with one to three random edits of its tree."""
    tree = yaml.safe_load(draw(st.sampled_from(EXAMPLES)).read_text())
    for _ in range(draw(st.integers(1, 3))):
        path, _value = draw(st.sampled_from(list(_paths(tree))[1:]))
        parent = tree
        for key in path[:-1]:
            parent = parent[key]
        edit = draw(st.sampled_from(["replace", "drop", "add"]))
        if edit == "drop":
            del parent[path[-1]]
        elif edit == "add" and isinstance(parent, dict):
            parent[draw(KEYS)] = draw(trees)
        else:
            parent[path[-1]] = draw(trees)
    return tree


@FUZZ
@given(tree=mutated_examples())
def test_mutated_example_scenes_load_or_raise_input_error(example_folder, tree):
    load(example_folder, yaml.safe_dump(tree, allow_unicode=True))


@FUZZ
@given(scene=st.sampled_from(EXAMPLES), data=st.data())
def test_example_scenes_with_changed_characters_load_or_raise_input_error(example_folder, scene, data):
    text = scene.read_text()
    for _ in range(data.draw(st.integers(1, 4))):
        at = data.draw(st.integers(0, len(text)))
        cut = data.draw(st.integers(0, 3))
        text = text[:at] + data.draw(st.text(max_size=3)) + text[at + cut:]
    load(example_folder, text)


def test_the_example_scenes_load(example_folder):
    """The fuzzed documents start from scenes that load: the mutations, not the copies, are refused."""
    for scene in EXAMPLES:
        shutil.copy(scene, example_folder / "scene.yaml")
        load_scene(example_folder / "scene.yaml")
