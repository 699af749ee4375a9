"""Material presets of scene.yaml (`objects[].material`).

Each preset is its own pydantic model so that a key that does not belong to a
preset (``yield_stress`` on jelly) is an error that names it. Defaults are
chosen so that a one-second example scene simulates in minutes on a 2-core CPU.
Units: pascals, kilograms per cubic metre, degrees, pascal-seconds.
"""
from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field


class _Elastic(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    youngs_modulus: float = Field(2.0e5, gt=0, description="Young's modulus E in Pa")
    poisson_ratio: float = Field(0.3, ge=0, lt=0.5, description="Poisson ratio nu, in [0, 0.5)")
    density: float = Field(1000.0, gt=0, description="density in kg/m^3")


class Jelly(_Elastic):
    """Hyperelastic solid that always returns to its rest shape."""

    preset: Literal["jelly"] = "jelly"
    model: Literal["fixed_corotated", "neo_hookean"] = Field("fixed_corotated", description="elastic energy")


class Metal(_Elastic):
    """von Mises plasticity with linear hardening: bends and keeps the dent."""

    preset: Literal["metal"] = "metal"
    youngs_modulus: float = Field(1.0e6, gt=0, description="Young's modulus E in Pa")
    density: float = Field(3000.0, gt=0, description="density in kg/m^3")
    yield_stress: float = Field(1.5e4, gt=0, description="von Mises yield stress in Pa")
    hardening: float = Field(0.1, ge=0, description="linear hardening: yield stress grows by this times E per unit plastic strain")


class Sand(_Elastic):
    """Drucker-Prager granular material."""

    preset: Literal["sand"] = "sand"
    density: float = Field(1600.0, gt=0, description="density in kg/m^3")
    friction_angle_deg: float = Field(30.0, gt=0, lt=90, description="internal friction angle in degrees")


class Plasticine(_Elastic):
    """von Mises plasticity with softening: kneads and keeps its new shape."""

    preset: Literal["plasticine"] = "plasticine"
    yield_stress: float = Field(5.0e3, gt=0, description="von Mises yield stress in Pa")
    softening: float = Field(0.1, ge=0, description="yield stress decays as exp(-softening * equivalent plastic strain)")


class Foam(_Elastic):
    """Viscoplastic foam (Perzyna over von Mises): squashes and slowly flows back less than it went.

    The overstress above yield relaxes with time constant viscosity / (2 mu),
    about 25 ms with these defaults.
    """

    preset: Literal["foam"] = "foam"
    youngs_modulus: float = Field(5.0e4, gt=0, description="Young's modulus E in Pa")
    density: float = Field(200.0, gt=0, description="density in kg/m^3")
    yield_stress: float = Field(2.0e3, gt=0, description="yield stress in Pa")
    viscosity: float = Field(1.0e3, gt=0, description="plastic viscosity in Pa s")


class Snow(_Elastic):
    """Stomakhin et al. 2013 snow: hardens under compression, crumbles under stretch."""

    preset: Literal["snow"] = "snow"
    youngs_modulus: float = Field(1.4e5, gt=0, description="Young's modulus E in Pa")
    poisson_ratio: float = Field(0.2, ge=0, lt=0.5, description="Poisson ratio nu, in [0, 0.5)")
    density: float = Field(400.0, gt=0, description="density in kg/m^3")
    critical_compression: float = Field(2.5e-2, gt=0, lt=1, description="theta_c: singular values clamp below 1 - theta_c")
    critical_stretch: float = Field(7.5e-3, gt=0, lt=1, description="theta_s: singular values clamp above 1 + theta_s")
    hardening: float = Field(10.0, ge=0, description="xi: stiffness grows as exp(xi (1 - J_p))")


class Rigid(BaseModel):
    """A body whose shape does not change: it moves as one (six degrees of freedom), so it has no
    elastic constants and no elastic wave bounds its time step."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)

    preset: Literal["rigid"] = "rigid"
    density: float = Field(1000.0, gt=0, description="density in kg/m^3")
    restitution: float = Field(
        0.0, ge=0, le=1, description="coefficient of restitution e against the ground, in [0, 1]: the speed at "
        "which the body's contact point leaves the ground over the speed at which it struck it. 0: it lands "
        "and stays; 1: it bounces back to the height it fell from; a ball dropped from h rebounds to e^2 h")


class Fracture(_Elastic):
    """Elastic solid with damage: tears apart where it is stretched past its toughness."""

    preset: Literal["fracture"] = "fracture"
    critical_stretch: float = Field(0.1, gt=0, description="principal stretch above 1 at which damage starts")
    toughness: float = Field(0.05, gt=0, description="further stretch over which damage grows to complete failure")


Material = Annotated[
    Union[Jelly, Metal, Sand, Plasticine, Foam, Snow, Rigid, Fracture],
    Field(discriminator="preset"),
]
PRESETS = ("jelly", "metal", "sand", "plasticine", "foam", "snow", "rigid", "fracture")
