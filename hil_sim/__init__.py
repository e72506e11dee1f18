"""Simulated amplifier + creep plant in its own process (``python -m hil_sim``).

It stands in for the hardware: the creep model (plus hidden effects, noise and
ADC quantization) streamed at a fixed rate over a pseudo-terminal (ASCII or
binary serial frames, or SLCAN) or python-can's virtual bus, with optional
fault injection and a ledger of every injected fault.
"""
from .plant import PlantConfig, PlantRecord, generate, make_input, parse_params
from .runner import run_virtual_plant

__all__ = ["PlantConfig", "PlantRecord", "generate", "make_input", "parse_params", "run_virtual_plant"]
