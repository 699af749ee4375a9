"""Loading a transformers model from a local folder, checked complete first (weights never come from a hub)."""
from __future__ import annotations

from pathlib import Path

from schemas import InputError

PROCESSOR_FILES = ("preprocessor_config.json", "processor_config.json")
"""Hub checkpoints carry the first; newer ``Processor.save_pretrained`` writes the second."""


def require_model_folder(model_dir: Path, kind: str, example: str, otherwise: str) -> None:
    """Raise InputError naming the missing file unless ``model_dir`` holds config.json and a processor config.

    kind: what the model is ("SAM"); example: a checkpoint that fits; otherwise: what to do without it.
    """
    fix = (f"put a transformers {kind} model (save_pretrained of the model and its processor, e.g. {example}) "
           f"in {model_dir}, or {otherwise}")
    if not (model_dir / "config.json").is_file():
        raise InputError(model_dir / "config.json", None, f"{kind} model file is missing", fix)
    if not any((model_dir / name).is_file() for name in PROCESSOR_FILES):
        raise InputError(model_dir / PROCESSOR_FILES[0], None, f"{kind} processor file is missing", fix)


def load_local_model(processor_class, model_class, model_dir: Path, device: str, kind: str, example: str,
                     otherwise: str):
    """(processor, model in eval mode on ``device``) from a checked local folder; never from a hub."""
    require_model_folder(model_dir, kind, example, otherwise)
    processor = processor_class.from_pretrained(model_dir, local_files_only=True)
    model = model_class.from_pretrained(model_dir, local_files_only=True).to(device).eval()
    return processor, model
