"""Random-access readers of global-shutter footage (a folder of images, a video, or arrays) with exact times.

Rolling-shutter composition (``rollcam.sim.compose``) reads rows of many neighbouring GS frames, so a
``Footage`` hands out frames by index, keeps the last few decoded in a small LRU cache, and knows each
frame's timestamp in integer ns: frame ``k`` is at ``round(k * 1e9 / fps)`` computed in closed form from an
exact ``Fraction`` frame rate, so frame 10 million is as exact as frame 1.
"""

from __future__ import annotations

import re
from collections import OrderedDict
from collections.abc import Sequence
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np
from rollcam.common.errors import ConfigError, SourceError
from rollcam.common.lifecycle import Closeable

from .codecs import bgr_to_rgb
from .timing import NS_PER_S

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".npy")
"""File types a footage folder may hold; other files in the folder are ignored."""

FpsLike = int | float | Fraction | str

# A video container's float fps (29.97002997...) is a rounded rational; 10,000 recovers 30000/1001 exactly.
_FPS_MAX_DENOMINATOR = 10_000
# Reading forward by grab() beats a container seek for short hops (seeks land on keyframes and decode on).
_VIDEO_MAX_SKIP = 64


def as_fps(fps: FpsLike, where: str = "fps") -> Fraction:
    """An exact positive frame rate from an int, float, ``Fraction`` or string like ``"30000/1001"``."""
    try:
        value = Fraction(fps)
    except (TypeError, ValueError, ZeroDivisionError):
        raise ConfigError(f"{where} must be a positive number or 'num/den', got {fps!r}") from None
    if isinstance(fps, float):
        value = value.limit_denominator(_FPS_MAX_DENOMINATOR)
    if value <= 0:
        raise ConfigError(f"{where} must be positive, got {fps!r}")
    return value


def natural_key(path: Path) -> list[object]:
    """Sort key that puts ``frame2`` before ``frame10``."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


def _read_image(path: Path) -> np.ndarray:
    """Decode one image file (or ``.npy`` array) with its own bit depth, colour as RGB."""
    if not path.is_file():
        raise SourceError(f"{str(path)!r}: footage frame file is missing")
    if path.suffix.lower() == ".npy":
        try:
            img = np.load(path, allow_pickle=False)
        except (OSError, ValueError, EOFError) as exc:
            raise SourceError(f"{str(path)!r}: cannot load footage array ({exc})") from None
        if img.ndim not in (2, 3):
            raise SourceError(f"{str(path)!r}: footage array must be HxW or HxWxC, got shape {img.shape!r}")
        return img
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SourceError(f"{str(path)!r}: cannot decode image (corrupt or unsupported file)")
    return bgr_to_rgb(img)


class _FolderReader:
    """Frames from a folder of image files in natural sort order."""

    def __init__(self, folder: Path) -> None:
        self.name = str(folder)
        self.files = sorted(
            (p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()),
            key=natural_key,
        )
        if not self.files:
            raise SourceError(f"{self.name!r}: folder holds no footage frames ({', '.join(IMAGE_SUFFIXES)})")

    def __len__(self) -> int:
        return len(self.files)

    def where(self, k: int) -> str:
        return str(self.files[k])

    def read(self, k: int) -> np.ndarray:
        return _read_image(self.files[k])

    def close(self) -> None:
        pass


class _VideoReader:
    """Frames from a video file through cv2.VideoCapture, read forward where possible."""

    def __init__(self, path: Path) -> None:
        self.name = str(path)
        self.cap: cv2.VideoCapture | None = cv2.VideoCapture(self.name)
        if not self.cap.isOpened():
            self.cap.release()
            self.cap = None
            raise SourceError(f"{self.name!r}: cannot open as a video (corrupt or unsupported container)")
        self.container_fps = float(self.cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.count = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        if self.count <= 0:
            # Some containers do not record a frame count; counting by grab() decodes no pixels to RGB.
            self.count = 0
            while self.cap.grab():
                self.count += 1
            self.cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
        if self.count <= 0:
            self.close()
            raise SourceError(f"{self.name!r}: video holds no frames")
        self.pos = 0  # index of the frame the next read() returns

    def __len__(self) -> int:
        return self.count

    def where(self, k: int) -> str:
        return f"{self.name} frame {k}"

    def read(self, k: int) -> np.ndarray:
        cap = self.cap
        if cap is None:
            raise SourceError(f"{self.name!r}: footage is closed")
        if not self.pos <= k <= self.pos + _VIDEO_MAX_SKIP:
            cap.set(cv2.CAP_PROP_POS_FRAMES, k)
            self.pos = k
        while self.pos < k:
            if not cap.grab():
                break
            self.pos += 1
        ok, img = cap.read() if self.pos == k else (False, None)
        if not ok or img is None:
            self.pos = -(_VIDEO_MAX_SKIP + 2)  # unknown position: the next read seeks
            raise SourceError(f"{self.name!r}: cannot decode frame {k} of {self.count}")
        self.pos = k + 1
        return bgr_to_rgb(img)

    def close(self) -> None:
        if self.cap is not None:
            self.cap.release()
            self.cap = None


class _ArrayReader:
    """Frames held in memory (synthetic footage in tests and benchmarks)."""

    def __init__(self, frames: Sequence[np.ndarray] | np.ndarray) -> None:
        self.name = "<arrays>"
        self.frames = frames
        if len(frames) == 0:
            raise SourceError("in-memory footage holds no frames")

    def __len__(self) -> int:
        return len(self.frames)

    def where(self, k: int) -> str:
        return f"<arrays>[{k}]"

    def read(self, k: int) -> np.ndarray:
        # A view: the caller's arrays are not copied (and the read-only flag stays on the view).
        return np.asarray(self.frames[k]).view()

    def close(self) -> None:
        pass


class Footage(Closeable):
    """Global-shutter footage at a known frame rate: frames by index, each with an exact ns timestamp.

    ``source`` is a folder of images (png/jpg/tif/bmp/npy, natural sort order; ``fps`` required) or a video
    file (``fps`` from the container unless given). Frames come out read-only, RGB(A) or single-channel, in
    the file's own dtype; every frame must have the first frame's shape and dtype.
    """

    def __init__(self, source: str | Path, fps: FpsLike | None = None, *, cache_frames: int = 8) -> None:
        path = Path(source)
        if path.is_dir():
            if fps is None:
                raise SourceError(
                    f"{str(path)!r}: a folder of frames has no frame rate; pass fps= (e.g. fps=32400)"
                )
            reader: _FolderReader | _VideoReader | _ArrayReader = _FolderReader(path)
        elif path.is_file():
            reader = _VideoReader(path)
            if fps is None:
                if reader.container_fps <= 0:
                    reader.close()
                    raise SourceError(f"{str(path)!r}: video reports no frame rate; pass fps=")
                fps = reader.container_fps
        else:
            raise SourceError(f"{str(path)!r}: no such footage file or folder")
        self._init(reader, fps, cache_frames)

    @classmethod
    def from_frames(
        cls, frames: Sequence[np.ndarray] | np.ndarray, fps: FpsLike, *, cache_frames: int = 8
    ) -> Footage:
        """Footage from frames already in memory (a list of arrays or one N x H x W [x C] array)."""
        self = cls.__new__(cls)
        self._init(_ArrayReader(frames), fps, cache_frames)
        return self

    def _init(self, reader: _FolderReader | _VideoReader | _ArrayReader, fps: FpsLike, cache: int) -> None:
        self._reader = reader
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()
        self._cache_frames = max(1, int(cache))
        try:
            self.fps = as_fps(fps)
            first = self._load(0, check=False)
        except Exception:
            reader.close()
            raise
        self.shape: tuple[int, ...] = first.shape
        self.dtype: np.dtype = first.dtype
        # time_ns(k) = round(k * 1e9 * den / num), done as floor((2 k 1e9 den + num) / (2 num)).
        self._num, self._den = self.fps.numerator, self.fps.denominator

    # ---- frames -------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self._reader)

    def __getitem__(self, k: int) -> np.ndarray:
        n = len(self)
        k = int(k)
        if k < 0:
            k += n
        if not 0 <= k < n:
            raise IndexError(f"footage frame {k} out of range (0..{n - 1})")
        self._check_open()
        frame = self._cache.get(k)
        if frame is not None:
            self._cache.move_to_end(k)
            return frame
        return self._load(k, check=True)

    def _load(self, k: int, check: bool) -> np.ndarray:
        # Read-only, so the cached array handed to many callers cannot be changed by one of them.
        frame = self._reader.read(k)
        if check and (frame.shape != self.shape or frame.dtype != self.dtype):
            raise SourceError(
                f"{self._reader.where(k)!r}: frame is {frame.shape!r} {frame.dtype}, "
                f"but the footage's first frame is {self.shape!r} {self.dtype}"
            )
        frame.flags.writeable = False
        self._cache[k] = frame
        if len(self._cache) > self._cache_frames:
            self._cache.popitem(last=False)
        return frame

    @property
    def frame_names(self) -> list[str] | None:
        """File names of a folder footage's frames in frame order (None for a video or in-memory frames)."""
        files = getattr(self._reader, "files", None)
        return None if files is None else [p.name for p in files]

    @property
    def height(self) -> int:
        """Frame height in pixels."""
        return int(self.shape[0])

    @property
    def width(self) -> int:
        """Frame width in pixels."""
        return int(self.shape[1])

    # ---- time ---------------------------------------------------------------------------------------
    def time_ns(self, k: int) -> int:
        """Timestamp of frame ``k``: ``round(k * 1e9 / fps)`` in exact integer arithmetic (halves up)."""
        return (2 * int(k) * NS_PER_S * self._den + self._num) // (2 * self._num)

    def times_ns(self, ks: np.ndarray) -> np.ndarray:
        """Timestamps of frames ``ks`` (int64 ns), the same closed form as ``time_ns``."""
        ks = np.asarray(ks, dtype=np.int64)
        if ks.size == 0:
            return ks.copy()
        k_max = int(np.abs(ks).max())
        if 2 * (k_max + 1) * NS_PER_S * self._den + self._num < 2**62:
            return (2 * ks * (NS_PER_S * self._den) + self._num) // (2 * self._num)
        # Python ints where int64 could overflow (long footage at an awkward rational fps).
        return np.array([self.time_ns(k) for k in ks.ravel().tolist()], dtype=np.int64).reshape(ks.shape)

    @property
    def span_ns(self) -> tuple[int, int]:
        """Timestamps of the first and the last frame."""
        return self.time_ns(0), self.time_ns(len(self) - 1)

    def index_at_or_before_ns(self, t_ns: np.ndarray) -> np.ndarray:
        """Index of the last frame whose timestamp is <= each time (int64); times must lie in ``span_ns``."""
        t = np.asarray(t_ns, dtype=np.int64)
        t0, t1 = self.span_ns
        bad = (t < t0) | (t > t1)
        if np.any(bad):
            raise SourceError(
                f"{self._reader.name!r}: times {t[bad][:5].tolist()!r} ns (of {int(bad.sum())}) lie outside "
                f"the footage's span [{t0}, {t1}] ns ({len(self)} frames at {float(self.fps):g} fps)"
            )
        # Float estimate, then exact correction against the closed-form times of the candidate frames.
        k_est = np.floor(t.astype(np.float64) * (float(self.fps) / NS_PER_S)).astype(np.int64)
        lo = max(int(k_est.min()) - 2, 0)
        hi = min(int(k_est.max()) + 3, len(self))
        table = self.times_ns(np.arange(lo, hi, dtype=np.int64))
        return lo + np.searchsorted(table, t, side="right").astype(np.int64) - 1

    # ---- lifecycle ----------------------------------------------------------------------------------
    closed_error = SourceError

    def _describe(self) -> str:
        return f"{self._reader.name!r}: footage"

    def _close(self) -> None:
        """Release the video or file handles and drop cached frames."""
        self._cache.clear()
        self._reader.close()

    def __repr__(self) -> str:
        size = "x".join(map(str, self.shape))
        return (
            f"Footage({self._reader.name!r}, {len(self)} frames {size} {self.dtype}, "
            f"fps={self.fps}{', closed' if self._closed else ''})"
        )
