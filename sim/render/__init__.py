"""The per-line renderer: one scene function evaluated at a vector of line times, and what it returns.

``renderer`` holds ``Renderer`` (the public entry; ``rollcam.sim.render.Renderer`` as before), ``result`` its
results, ``flicker_renderer`` the renderer of modulated lights; ``tables`` turns scene data into the flat tables
the numba kernels read (``lines``, ``actors``, ``body``, ``props``, ``parts``, ``texture``, ``world``,
``egoblur``, ``flicker_mix``), ``paint`` and ``composite`` are the passes over them, and ``shader`` loads the C
background shader (``rollcam_shade.c``, built into ``librollcam_shade.so`` beside it).
"""

from .flicker_renderer import FlickerRenderer  # registers itself as the renderer of modulated lights
from .renderer import LinearFrame, LineTruth, Renderer, RenderResult, encode_linear, srgb_lut

__all__ = ["FlickerRenderer", "LineTruth", "LinearFrame", "RenderResult", "Renderer", "encode_linear", "srgb_lut"]
