"""The contract between physmotion's stages: scene.yaml, the HDF5 artifacts, program conventions."""
from .program import InputError, resolve_device, run_main, stage_parser
from .scene import Scene, config_hash, load_scene, scene_json_schema, stage_keys

__all__ = ["InputError", "Scene", "config_hash", "load_scene", "resolve_device", "run_main",
           "scene_json_schema", "stage_keys", "stage_parser"]
