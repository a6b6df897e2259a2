"""picamera2's buffer allocators, accepted: the stand-in's buffers are numpy arrays made per frame.

Scripts choose an allocator to control how frame buffers are allocated (``Picamera2(allocator=...)``,
``picam2.allocator = ...``); here every one keeps the configurations it was used with by ``buffer_key`` (the
configuration's ``use_case``) so that ``deallocate(key)`` has something to drop, and nothing else changes.
"""

from __future__ import annotations

from typing import Any


class Allocator:
    """The base allocator: allocates nothing the stand-in needs."""

    def __init__(self) -> None:
        self.buffer_key: str | None = None
        self.allocated: dict[str, Any] = {}

    def allocate(self, config: dict[str, Any]) -> None:
        """Note the configuration buffers were made for (under ``buffer_key`` or its use case)."""
        self.allocated[self.buffer_key or str(config.get("use_case"))] = config

    def deallocate(self, key: str | None = None) -> None:
        """Forget the buffers of ``key`` (all when None)."""
        if key is None:
            self.allocated.clear()
        else:
            self.allocated.pop(key, None)

    def close(self) -> None:
        """Release everything."""
        self.deallocate()


class DmaAllocator(Allocator):
    """picamera2's default allocator (dma-heap buffers on a Pi)."""


class LibcameraAllocator(Allocator):
    """libcamera's own frame-buffer allocator, made for a camera (``LibcameraAllocator(picam2.camera)``)."""

    def __init__(self, camera: Any = None) -> None:
        super().__init__()
        self.camera = camera


class PersistentAllocator(DmaAllocator):
    """Keeps each configuration's buffers, so that switching back to one reuses them."""


__all__ = ["Allocator", "DmaAllocator", "LibcameraAllocator", "PersistentAllocator"]
