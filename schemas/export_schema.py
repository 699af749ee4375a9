"""Write docs/scene.schema.json, the JSON Schema of scene.yaml for editors (e.g. the YAML language server).

Usage: python -m schemas.export_schema [OUT]
"""
import json
import sys
from pathlib import Path

from .scene import scene_json_schema

if __name__ == "__main__":
    out = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).resolve().parents[1] / "docs" / "scene.schema.json")
    out.write_text(json.dumps(scene_json_schema(), indent=2) + "\n")
    print(f"wrote {out}")
