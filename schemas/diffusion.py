"""Settings of the diffusion enhancement backend (scene.yaml `enhance.diffusion`).

Model paths resolve in this order: this section, then the environment
variables named in each field's description, then the local Hugging Face cache.
Nothing is ever downloaded.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

from pydantic import BaseModel, ConfigDict, Field


class DiffusionModels(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    stable_diffusion: Optional[Path] = Field(None, description="Stable Diffusion 2.1 folder (env PHYSMOTION_SD_PATH)")
    controlnet_depth: Optional[Path] = Field(None, description="depth ControlNet folder (env PHYSMOTION_CONTROLNET_DEPTH)")
    controlnet_canny: Optional[Path] = Field(None, description="Canny ControlNet folder (env PHYSMOTION_CONTROLNET_CANNY)")


class LoraSettings(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    enabled: bool = Field(False, description="personalise the UNet on the object (pm-lora) before sampling")
    steps: int = Field(1500, gt=0, description="training steps (paper: 1500)")
    learning_rate: float = Field(1e-6, gt=0, description="learning rate (paper: 1e-6)")
    rank: int = Field(4, gt=0, description="LoRA rank")


class DiffusionSettings(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    models: DiffusionModels = DiffusionModels()
    resolution: int = Field(768, gt=0, multiple_of=8, description="sampling width in pixels (SD 2.1: 768)")
    steps: int = Field(50, gt=0, description="DDIM sampling steps")
    guidance_scale: float = Field(7.5, ge=1, description="classifier-free guidance weight of the enhanced branch")
    negative_prompt: str = Field("", description="prompt of the unconditional half of classifier-free guidance")
    inversion_total_steps: int = Field(1000, gt=0, description="training timesteps spanned by inversion")
    inversion_stride: int = Field(20, gt=0, description="timestep stride of DDIM+ inversion (paper: 20)")
    tau_f: float = Field(0.8, ge=0, le=1, description="fraction of steps with residual-feature injection")
    tau_a: float = Field(0.5, ge=0, le=1, description="fraction of steps with self-attention Q/K injection")
    keyframe_window: int = Field(5, gt=0, description="one random keyframe per window of this many frames")
    controlnet_scale: float = Field(1.0, ge=0, description="ControlNet conditioning scale")
    canny_thresholds: tuple[int, int] = Field((100, 200), description="low and high thresholds of cv2.Canny")
    frame_batch: int = Field(4, gt=0, description="frames per UNet call (each call holds 3 branches of them)")
    seed: int = Field(0, description="seed of keyframe draws and noise")
    lora: LoraSettings = LoraSettings()
