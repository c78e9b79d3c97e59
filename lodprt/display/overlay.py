"""The viewer's overlay (``lodprt view``): its text in the top-left corner and the criterion's sliders in the
bottom-left one, drawn with Pillow into textures and blended over the frame; the sliders' layout and hit tests."""

from __future__ import annotations

import dataclasses

import numpy as np

from lodprt.runtime.criteria import CRITERIA

_OVERLAY_VERTEX = """
#version 330
in vec2 in_pos;
in vec2 in_uv;
out vec2 v_uv;
void main() { gl_Position = vec4(in_pos, 0.0, 1.0); v_uv = in_uv; }
"""
_OVERLAY_FRAGMENT = """
#version 330
uniform sampler2D text;
in vec2 v_uv;
out vec4 f_col;
void main() { f_col = texture(text, v_uv); }
"""


@dataclasses.dataclass(frozen=True)
class Slider:
    """A horizontal slider in framebuffer pixels (origin top left, y down): ``rect`` = (x, y, width, height) of its
    track, the part a press must start in; ``value_at`` maps an x position linearly onto [lo, hi], clamped at the
    ends."""

    name: str  # the ViewerState field it sets
    label: str
    rect: tuple[float, float, float, float]
    lo: float = 0.0
    hi: float = 1.0

    def contains(self, x: float, y: float) -> bool:
        x0, y0, w, h = self.rect
        return x0 <= x <= x0 + w and y0 <= y <= y0 + h

    def value_at(self, x: float) -> float:
        x0, _, w, _ = self.rect
        t = min(max((x - x0) / w, 0.0), 1.0)
        return self.lo + t * (self.hi - self.lo)

    def fraction(self, value: float) -> float:
        """How much of the track is filled for ``value`` (0 to 1; values outside the range fill none or all)."""
        return min(max((value - self.lo) / (self.hi - self.lo), 0.0), 1.0)


SLIDER_MARGIN, SLIDER_ROW, SLIDER_LABEL, SLIDER_VALUE = 6, 16, 72, 44  # pixels: edge gap, row height, text widths


def slider_layout(width: int, height: int, *, alpha: bool = True, knobs=None) -> tuple[Slider, ...]:
    """A criterion's sliders in the bottom-left corner of a ``width`` x ``height`` pixel window: one per knob with
    a range (``knobs``: ``Criterion.KNOBS``; default the error bound and, with ``alpha``, the thesis criterion's
    alpha), each a label column, the track, then the value; the track is 160 pixels wide, less in a narrow window
    (at least 40)."""
    track = max(40, min(160, width - 2 * SLIDER_MARGIN - SLIDER_LABEL - SLIDER_VALUE - 8))
    x0 = SLIDER_MARGIN + 4 + SLIDER_LABEL
    if knobs is None:
        knobs = CRITERIA["thesis" if alpha else "screen"].KNOBS
    rows = [(k.name, k.name.replace("_", " "), k.range) for k in knobs if k.range is not None]
    top = height - SLIDER_MARGIN - 4 - SLIDER_ROW * len(rows)
    return tuple(Slider(name, label, (x0, top + i * SLIDER_ROW + 2, track, SLIDER_ROW - 4), *span)
                 for i, (name, label, span) in enumerate(rows))


def slider_panel(sliders, values) -> tuple[object, tuple[int, int]]:
    """The sliders drawn with Pillow: an RGBA image of the panel behind them and its top-left corner (pixels)."""
    from PIL import Image, ImageDraw

    x_end = max(s.rect[0] + s.rect[2] for s in sliders) + 4 + SLIDER_VALUE
    y0 = min(s.rect[1] for s in sliders) - 4
    y_end = max(s.rect[1] + s.rect[3] for s in sliders) + 4
    left, top = SLIDER_MARGIN, int(y0)
    img = Image.new("RGBA", (int(x_end) - left, int(y_end) - top), (0, 0, 0, 150))
    draw = ImageDraw.Draw(img)
    for s in sliders:
        x, y, w, h = (int(round(v)) for v in s.rect)
        x, y = x - left, y - top
        value = values[s.name]
        draw.text((4, y + h / 2 - 6), s.label, fill=(255, 255, 255, 255))
        draw.rectangle((x, y + 2, x + w - 1, y + h - 3), fill=(70, 70, 70, 255), outline=(150, 150, 150, 255))
        fill = int(round(s.fraction(value) * (w - 2)))
        if fill > 0:
            draw.rectangle((x + 1, y + 3, x + fill, y + h - 4), fill=(255, 200, 60, 255))
        draw.text((x + w + 4, y + h / 2 - 6), f"{value:.3g}", fill=(255, 255, 255, 255))
    return img, (left, top)


class Overlay:
    """Text in the top-left corner and the sliders in the bottom-left one: drawn with Pillow into textures (redrawn
    only when they change), blended over the frame."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.prog = ctx.program(vertex_shader=_OVERLAY_VERTEX, fragment_shader=_OVERLAY_FRAGMENT)
        self.vbo = ctx.buffer(reserve=4 * 4 * 4)
        self.vao = ctx.vertex_array(self.prog, [(self.vbo, "2f 2f", "in_pos", "in_uv")])
        self.tex = {}  # what -> (key it was drawn from, top-left pixel, texture)

    def draw(self, text: str, size: tuple[int, int], sliders=(), values=None) -> None:
        from PIL import Image, ImageDraw

        def text_image():
            lines = text.split("\n")
            img = Image.new("RGBA", (8 + 7 * max(len(s) for s in lines), 6 + 13 * len(lines)), (0, 0, 0, 150))
            ImageDraw.Draw(img).multiline_text((4, 3), text, fill=(255, 255, 255, 255), spacing=2)
            return img, (0, 0)

        self._blit("text", text, text_image, size)
        if sliders:
            key = (tuple(sliders), tuple(values[s.name] for s in sliders))
            self._blit("sliders", key, lambda: slider_panel(sliders, values), size)

    def _blit(self, what, key, make, size) -> None:
        """Draw the image ``make()`` returns at its top-left pixel position; made again only when ``key`` changed."""
        import moderngl
        from PIL import Image

        old = self.tex.get(what)
        if old is None or old[0] != key:
            img, pos = make()
            if old is not None:
                old[2].release()
            tex = self.ctx.texture(img.size, 4, img.transpose(Image.FLIP_TOP_BOTTOM).tobytes())
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)  # one texel per pixel: crisp text
            self.tex[what] = old = (key, pos, tex)
        _, (px, py), tex = old
        w, h = tex.size
        x0, x1 = -1 + 2 * px / size[0], -1 + 2 * (px + w) / size[0]
        y1, y0 = 1 - 2 * py / size[1], 1 - 2 * (py + h) / size[1]
        self.vbo.write(np.array([x0, y0, 0, 0, x1, y0, 1, 0, x0, y1, 0, 1, x1, y1, 1, 1], np.float32).tobytes())
        self.ctx.disable(moderngl.DEPTH_TEST)
        self.ctx.enable(moderngl.BLEND)
        self.ctx.blend_func = moderngl.SRC_ALPHA, moderngl.ONE_MINUS_SRC_ALPHA
        tex.use(0)
        self.prog["text"].value = 0
        self.vao.render(moderngl.TRIANGLE_STRIP)
        self.ctx.disable(moderngl.BLEND)
        self.ctx.enable(moderngl.DEPTH_TEST)
