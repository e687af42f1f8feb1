"""Writing an animated GIF frame by frame, holding one frame at a time.

imageio's Pillow writer keeps every frame until the file is closed (Pillow's
``save_all`` compares and writes them all at the end): a 5 001-frame episode of the
MuJoCo pendulum held 4.5 GB. :class:`GifStream` writes each frame as it comes, with
Pillow's GIF encoder (``GifImagePlugin.getheader``/``getdata``, its frame-at-a-time
interface):

* the first frame whole, its palette the file's global colour table;
* each later frame as the rectangle that changed since the previous one, with its own
  colour table (a frame of at most 256 colours is stored exactly; a richer one —
  MuJoCo's shading — is reduced to 256 by Pillow's median cut, as imageio does);
* a frame identical to the previous one as one unchanged pixel, so every frame the
  caller appends is a frame of the file, with its delay.

Delays are whole centiseconds (GIF's unit), rounded so that frame ``k`` starts at
``k / fps`` to the nearest centisecond: 30 fps plays as 3, 3, 4, 3, 3, 4, … cs. Browsers
show a delay under 2 cs as 10 cs, so a GIF plays at most 50 frames per second.
"""

from __future__ import annotations

from pathlib import Path
from typing import IO

import numpy as np
from numpy.typing import NDArray
from PIL import GifImagePlugin, Image


class GifStream:
    """An animated GIF at ``path``, ``fps`` frames per second, looping forever.

    Use as a context manager (or call :meth:`close`): :meth:`append` writes a
    ``(height, width, 3)`` uint8 frame; every frame has the first one's size.
    """

    def __init__(self, path: str | Path, fps: float) -> None:
        if not fps > 0:
            raise ValueError(f"fps must be positive; got {fps!r}")
        self.path, self.fps = Path(path), float(fps)
        self.frames = 0
        self._file: IO[bytes] | None = open(self.path, "wb")   # closed in close()
        self._previous: NDArray[np.uint8] | None = None

    def __enter__(self) -> GifStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def append(self, frame: NDArray[np.uint8]) -> None:
        """Write ``frame`` (``(height, width, 3)`` uint8) as the next frame."""
        if self._file is None:
            raise ValueError("the GIF is closed")
        frame = np.asarray(frame)
        if frame.ndim != 3 or frame.shape[2] != 3 or frame.dtype != np.uint8:
            raise ValueError(f"a frame must be an (height, width, 3) uint8 array; got "
                             f"{frame.dtype} of shape {frame.shape}")
        previous = self._previous
        if previous is not None and previous.shape != frame.shape:
            raise ValueError(f"every frame must be {previous.shape[1]}x{previous.shape[0]}; "
                             f"got {frame.shape[1]}x{frame.shape[0]}")
        c0, r0, c1, r1 = _changed(previous, frame)
        image = Image.fromarray(np.ascontiguousarray(frame[r0:r1, c0:c1])) \
            .convert("P", palette=Image.Palette.ADAPTIVE)
        delay = 10 * (round(100 * (self.frames + 1) / self.fps)
                      - round(100 * self.frames / self.fps))          # milliseconds, whole cs
        if previous is None:
            header, _ = GifImagePlugin.getheader(image, info={"loop": 0, "duration": delay})
            self._file.writelines(header)
        self._file.writelines(GifImagePlugin.getdata(
            image, offset=(c0, r0), duration=delay, include_color_table=previous is not None))
        self._previous = frame.copy()
        self.frames += 1

    def close(self) -> None:
        """End the file (GIF's trailer) and close it; a GIF with no frame is removed."""
        if self._file is None:
            return
        if self.frames:
            self._file.write(b";")
        self._file.close()
        self._file = None
        if not self.frames:
            self.path.unlink(missing_ok=True)


def _changed(previous: NDArray[np.uint8] | None, frame: NDArray[np.uint8]
             ) -> tuple[int, int, int, int]:
    """The columns and rows ``(c0, r0, c1, r1)`` (ends excluded) of the smallest rectangle
    holding every pixel that differs from ``previous`` (all of ``frame`` for the first; one
    pixel where nothing changed)."""
    height, width = frame.shape[:2]
    if previous is None:
        return 0, 0, width, height
    changed = np.any(frame != previous, axis=2)
    rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
    if not rows.size:
        return 0, 0, 1, 1
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1
