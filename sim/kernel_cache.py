"""What numba's on-disk cache holds of rollcam's kernels: whether the renderer compiles on its next use.

The commands read it to say, before a render, that the first one on a machine compiles for a while
(``rollcam.host.commands.compile_notice``); the cache files themselves are ``_jitcache``'s to find and keep fresh.
"""

from __future__ import annotations


def renderer_cache_cold() -> bool:
    """True when numba holds no cached machine code for the renderer's entry kernel (the next render compiles)."""
    from ._jitcache import cache_index  # numba and the kernels load only when asked, not with the module
    from .render.lines import render_lines_kernel

    index = cache_index(render_lines_kernel)  # numba keeps one index file per cached function
    return index is not None and not index.exists()
