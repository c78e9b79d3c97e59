"""Pictures to files: one frame (PNG tone-mapped or linear ``.npy``) and turntables (PNG sequences, GIF, H.264 MP4
through the optional imageio-ffmpeg), with the output checks every command shares (suffix, folder, no clobbering
without ``overwrite``)."""

from __future__ import annotations

import contextlib
import logging
import os
import re
import time
from pathlib import Path

import numpy as np

from lodprt.display.render import Renderer, check_size
from lodprt.runtime.frames import auto_white
from lodprt.errors import LodprtError
from lodprt.runtime.camera import orbit, rotate_about
from lodprt.runtime.direct_light import DEFAULT_INTERPOLATION
from lodprt.runtime.sources import frame_source

log = logging.getLogger(__name__)


def check_output(path, suffixes: tuple[str, ...], *, overwrite: bool | None, option: str = "overwrite=True") -> Path:
    """The output path, refused (LodprtError naming it) for a suffix not among ``suffixes`` (in any case), a
    missing folder, a folder, or an existing file without ``overwrite`` (None: not checked here). ``option`` is what
    the caller calls the permission to replace (the CLI's ``--overwrite``)."""
    path = Path(path)
    if path.suffix.lower() not in [s.lower() for s in suffixes]:
        raise LodprtError(f"{path}: the output must end in {' or '.join(suffixes)}")
    if not path.parent.is_dir():
        raise LodprtError(f"{path}: the folder {path.parent} does not exist")
    refuse_replacing(path, overwrite, option)
    return path


def refuse_replacing(path, overwrite: bool | None, option: str = "overwrite=True") -> None:
    """Refuse an output ``path`` that is a folder (a file never replaces one, ``overwrite`` or not) or, unless
    ``overwrite`` (None: not checked), an existing file."""
    if Path(path).is_dir():
        raise LodprtError(f"{path}: is a folder; the output must be a file ({option} replaces a file, never a "
                          "folder)")
    if overwrite is not None and Path(path).exists() and not overwrite:
        raise LodprtError(f"{path}: already exists; pass {option} to replace it")


EXR_EXTRA = "pip install 'lodprt[exr]'"
#: outputs holding the linear radiance (float32, background 0, no overlays) rather than a tone-mapped picture
LINEAR_SUFFIXES = (".npy", ".exr")


def check_exr() -> None:
    """LodprtError naming the extra when the optional ``openexr`` package is missing (before any work)."""
    try:
        import OpenEXR  # noqa: F401
    except ImportError as exc:
        raise LodprtError(f"writing .exr needs the optional openexr package; {EXR_EXTRA}") from exc


def write_exr(path, image: np.ndarray) -> None:
    """(H, W, 3) linear radiance -> an OpenEXR file of float32 R, G, B channels (ZIP compressed, lossless), row 0
    at the top, through the optional ``openexr`` package."""
    check_exr()
    import OpenEXR

    rgb = np.ascontiguousarray(np.asarray(image, np.float32)[:, :, :3])
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": rgb}) as f:
        f.write(str(path))


def save_image(path, image: np.ndarray) -> None:
    """(H, W, 3) uint8 -> PNG, or float32 linear -> .npy or .exr (float32 RGB)."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
        np.save(path, np.asarray(image, np.float32))
    elif path.suffix.lower() == ".exr":
        write_exr(path, image)
    else:
        from PIL import Image

        Image.fromarray(np.asarray(image, np.uint8)).save(path)


VIDEO_EXTRA = "pip install 'lodprt[video]'"
#: a GIF stores each frame's delay as a 16-bit count of hundredths of a second: the slowest rate it can hold
GIF_MIN_FPS = 100.0 / 65535


def check_fps(fps, suffix: str = "") -> float:
    """``fps`` as a float, refused (LodprtError naming --fps) unless a finite positive number: the one check every
    turntable output makes before any work, the frame rate of ``suffix`` ".gif" also no slower than a GIF holds."""
    try:
        rate = float(fps)
    except (TypeError, ValueError):
        rate = float("nan")
    if not (np.isfinite(rate) and rate > 0):
        raise LodprtError(f"--fps {fps}: must be a positive number of frames per second")
    if suffix.lower() == ".gif" and rate < GIF_MIN_FPS:
        raise LodprtError(f"--fps {fps}: a GIF holds no slower rate than {GIF_MIN_FPS:.4g} frames per second")
    return rate


def partial_path(path: Path) -> Path:
    """The hidden file beside ``path`` an output is written to before it is renamed into place."""
    return path.with_name(f".{path.stem}.partial{path.suffix}")


@contextlib.contextmanager
def written_in_place(path):
    """Yield ``path``'s partial file to write; when the block ends it is renamed onto ``path`` (os.replace: an old
    file there stays whole until then), when it raises it is removed and ``path`` is left as it was."""
    partial = partial_path(Path(path))
    try:
        yield partial
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    os.replace(partial, path)


def remove_stale_frames(folder: Path, prefix: str, suffix: str, frames: int) -> int:
    """Remove from ``folder`` the numbered frames ``{prefix}{k:04d}{suffix}`` with k >= ``frames`` that an earlier,
    longer turntable left (only files named exactly as the turntable names its frames; nothing else is touched).
    Returns how many were removed."""
    pattern = re.compile(re.escape(prefix) + r"(\d{4,})" + re.escape(suffix))
    removed = 0
    for path in sorted(folder.iterdir()):
        m = pattern.fullmatch(path.name)
        # f"{k:04d}" round trip: "frame_00001.png" is no name the turntable writes
        if m and f"{int(m[1]):04d}" == m[1] and int(m[1]) >= frames and path.is_file():
            path.unlink()
            removed += 1
    return removed


def even_frame(image: np.ndarray) -> np.ndarray:
    """``image`` padded (edge pixels repeated) to even width and height, as H.264 in yuv420p needs."""
    h, w = image.shape[:2]
    return np.pad(image, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge") if (h | w) % 2 else image


class VideoWriter:
    """H.264 MP4 (yuv420p, playable everywhere) through the optional imageio-ffmpeg: :meth:`send` (H, W, 3) uint8
    frames of one size, then :meth:`close`. Written to a hidden partial file next to ``path`` and renamed into
    place on close, so an interrupted turntable leaves no half video (and replaces nothing). LodprtError naming
    the extra when imageio-ffmpeg is not installed."""

    def __init__(self, path, *, fps: float):
        self.path = Path(path)
        try:
            import imageio_ffmpeg
        except ImportError as exc:
            raise LodprtError(f"{self.path}: writing .mp4 needs the optional imageio-ffmpeg; {VIDEO_EXTRA}") from exc
        self.ffmpeg, self.fps = imageio_ffmpeg, check_fps(fps)
        self.partial = partial_path(self.path)
        self.gen = None
        self.frames = 0

    def send(self, image: np.ndarray) -> None:
        image = np.ascontiguousarray(even_frame(np.asarray(image, np.uint8)))
        if self.gen is None:
            h, w = image.shape[:2]
            self.gen = self.ffmpeg.write_frames(str(self.partial), (w, h), fps=float(self.fps), quality=8,
                                                macro_block_size=1, ffmpeg_log_level="error")
            self.gen.send(None)
        self.gen.send(image)
        self.frames += 1

    def close(self) -> Path:
        if self.gen is None:
            raise LodprtError(f"{self.path}: no frames to write")
        self.gen.close()
        os.replace(self.partial, self.path)
        return self.path

    def abort(self) -> None:
        if self.gen is not None:
            try:
                self.gen.close()
            except Exception as exc:  # noqa: BLE001 - ffmpeg may already have stopped; nothing to keep
                log.debug("ffmpeg on %s: %s", self.partial, exc)
        self.partial.unlink(missing_ok=True)


def render_to_file(store, out, *, lights, camera, colors=None, error_bound: float | None = None, alpha: float | None = None,
                   criterion="screen", interpolation: str = DEFAULT_INTERPOLATION, target_psnr=None,
                   outside: str = "clamp",
                   lod: bool = True, overwrite: bool = False, **draw) -> dict:
    """``lodprt render``: one frame of ``store`` (view cut unless ``lod`` is False) to ``out`` (.png tone-mapped;
    .npy linear (H, W, 3) float32; .exr the same radiance as OpenEXR float32 RGB, needs the ``exr`` extra).
    ``draw`` keywords go to ``Renderer.draw``. Returns the frame's stats."""
    out = check_output(out, (".png", ".npy", ".exr"), overwrite=overwrite)
    if out.suffix.lower() == ".exr":
        check_exr()
    source = frame_source(store, error_bound=error_bound, alpha=alpha, lod=lod, criterion=criterion,
                          interpolation=interpolation, target_psnr=target_psnr, outside=outside,
                          white=draw.get("white"))  # the cut's errors in the picture's white
    source.set_lights(lights, colors)
    cam = source.set_camera(camera) or camera
    linear = out.suffix.lower() in LINEAR_SUFFIXES
    with Renderer() as renderer:
        check_size((cam.width, cam.height), renderer.ctx)  # a size the context cannot draw fails before the frame
        frame = source.update()
        if draw.get("white") is None and not linear:
            draw["white"] = source.white or auto_white(frame.radiance)
        t0 = time.perf_counter()
        image = renderer.image(frame, linear=linear, **draw)
        ms = 1e3 * (time.perf_counter() - t0)
    save_image(out, image)
    return dict(frame.stats, ms_draw=ms, lod=bool(getattr(source, "lod", False)))


def turntable(store, out, *, lights, camera, colors=None, frames: int = 36, light_turns: float = 1.0,
              fps: float = 12.0, error_bound: float | None = None, alpha: float | None = None, lod: bool = True,
              criterion="screen", interpolation: str = DEFAULT_INTERPOLATION, target_psnr=None,
              outside: str = "clamp",
              overwrite: bool = False, **draw) -> tuple[Path, int]:
    """``lodprt turntable``: ``frames`` views of one camera orbit about the target's vertical axis, the lights
    turning ``light_turns`` times the other way about the same axis (clamped to the sampled light region by the
    run time). ``out`` a folder (created; frame_0000.png, ...), a .gif (imageio), an .mp4 (H.264 through the
    optional imageio-ffmpeg, ``VideoWriter``; odd sizes padded to even) or ``NAME.exr``: the linear radiance of
    every frame as OpenEXR float32 RGB, ``NAME_0000.exr``, ``NAME_0001.exr``, ... beside it (the ``exr`` extra). One run time for the whole orbit, so the
    view cut moves incrementally from frame to frame and the white point stays fixed. A GIF or MP4 is written to a
    partial file renamed into place at the end (a failed run replaces nothing); with ``overwrite`` the numbered
    frames of a sequence that this run did not write (an earlier, longer one's) are removed. Returns the path written
    and how many such stale frames were removed."""
    out = Path(out)
    check_fps(fps, out.suffix)  # every output kind, before any file is touched or frame drawn
    if not np.isfinite(light_turns):  # named here: a nan turn reached the lights' check as nan positions
        raise LodprtError(f"--light-turns {light_turns}: must be a finite number of turns")
    if frames < 1:
        raise LodprtError(f"--frames {frames}: must be >= 1")
    gif, video, exr = out.suffix.lower() == ".gif", None, None
    if out.suffix.lower() == ".exr":
        exr = exr_sequence(out, frames, overwrite=overwrite)
    elif gif:
        check_output(out, (".gif",), overwrite=overwrite)
        import imageio.v3 as iio
    elif out.suffix.lower() == ".mp4":
        video = VideoWriter(check_output(out, (".mp4",), overwrite=overwrite), fps=fps)
    elif out.suffix:
        raise LodprtError(f"{out}: give a folder (PNG sequence), a .gif, an .mp4 or an .exr (EXR sequence) path")
    elif out.exists() and (not out.is_dir() or (any(out.iterdir()) and not overwrite)):
        raise LodprtError(f"{out}: already exists and is not an empty folder; pass overwrite=True to write into it")
    elif not out.parent.is_dir():
        raise LodprtError(f"{out}: the folder {out.parent} does not exist")
    lights = np.asarray(lights, np.float64).reshape(-1, 3)
    source = frame_source(store, error_bound=error_bound, alpha=alpha, lod=lod, criterion=criterion,
                          interpolation=interpolation, target_psnr=target_psnr, outside=outside,
                          white=draw.get("white"))  # the cut's errors in the picture's white
    images = []
    with Renderer() as renderer, _aborting(video):
        for k in range(frames):
            a = 2 * np.pi * k / frames
            source.set_lights([rotate_about(p, camera.target, camera.up, -light_turns * a) for p in lights], colors)
            source.set_camera(orbit(camera, a))
            frame = source.update()
            kw = dict(draw)
            if kw.get("white") is None:
                kw["white"] = source.white or auto_white(frame.radiance)
            if exr is not None:
                write_exr(exr[k], renderer.image(frame, linear=True, per_vertex=kw.get("per_vertex", False)))
                continue
            img = renderer.image(frame, **kw)
            if gif:
                images.append(img)
            elif video is not None:
                video.send(img)
            else:
                out.mkdir(exist_ok=True)
                save_image(out / f"frame_{k:04d}.png", img)
        if video is not None:
            video.close()
    if gif:
        with written_in_place(out) as partial:
            iio.imwrite(partial, np.stack(images), extension=".gif", duration=1000.0 / fps, loop=0)
    removed = 0
    if exr is not None:
        removed = remove_stale_frames(out.parent, f"{out.stem}_", ".exr", frames) if overwrite else 0
        out = exr[0].with_name(f"{out.stem}_0000..{frames - 1:04d}.exr")
    elif not gif and video is None:
        removed = remove_stale_frames(out, "frame_", ".png", frames) if overwrite else 0
    return out, removed


def exr_sequence(out: Path, frames: int, *, overwrite: bool) -> list[Path]:
    """The files of an EXR turntable ``out`` = NAME.exr: NAME_0000.exr ... beside it, checked before any work (the
    folder exists, the extra is installed, no file replaced without ``overwrite``)."""
    check_exr()
    if not out.parent.is_dir():
        raise LodprtError(f"{out}: the folder {out.parent} does not exist")
    names = [out.with_name(f"{out.stem}_{k:04d}.exr") for k in range(frames)]
    there = [n for n in names if n.exists()]
    if there and not overwrite:
        raise LodprtError(f"{there[0]}: already exists; pass overwrite=True to replace the sequence")
    return names


@contextlib.contextmanager
def _aborting(video):
    """Remove ``video``'s partial file when the block raises (a no-op for ``None``)."""
    try:
        yield
    except BaseException:
        if video is not None:
            video.abort()
        raise
