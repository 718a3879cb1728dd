"""The one place an OpenGL context is made (EGL, moderngl), and shader loading with readable errors.

Shaders live in ``simulator/shaders/*.vert|*.frag`` (package data); defines are injected
after the ``#version`` line followed by ``#line 2`` so compiler line numbers match the file.
"""

from __future__ import annotations

import importlib.resources
import re

from simulator.core.errors import InputError, VimsimError

__all__ = ["EGL_PACKAGES", "ShaderError", "create_context", "load_shader_source"]

#: Debian packages that provide headless EGL + OpenGL (Mesa llvmpipe without a GPU).
EGL_PACKAGES = "libegl1 libgl1-mesa-dri"


class ShaderError(VimsimError, RuntimeError):
    """A shader failed to compile or link; the message names the file and quotes the line
    (an internal error, under the package's root :class:`simulator.core.errors.VimsimError`)."""


def create_context():
    """The one place an OpenGL context is created: standalone moderngl over EGL (headless).

    Returns a ``moderngl.Context`` (OpenGL >= 4.3 core: storage buffers). Raises InputError
    naming the Debian packages to install when EGL or a GL driver is missing.
    """
    try:
        import moderngl
    except ImportError as e:  # pragma: no cover - a dependency of the package
        raise InputError(f"moderngl is not installed ({e}); pip install moderngl") from None
    try:
        ctx = moderngl.create_context(standalone=True, backend="egl", require=430)
    except Exception as e:  # noqa: BLE001 - glcontext raises plain Exceptions
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise InputError(
            f"no headless OpenGL 4.3 over EGL ({msg}); on Debian/Ubuntu install {EGL_PACKAGES} "
            f"(apt-get install {EGL_PACKAGES})"
        ) from None
    return ctx


def load_shader_source(name: str, defines: dict[str, object] | None = None) -> str:
    """Source of ``simulator/shaders/<name>`` with ``#define``s injected after ``#version``.

    The injected block is followed by ``#line 2`` so that compiler line numbers match
    the file's.
    """
    src = importlib.resources.files("simulator").joinpath("shaders", name).read_text()
    first, _, rest = src.partition("\n")
    if not first.startswith("#version"):
        raise ShaderError(f"shaders/{name}:1: first line must be #version; got {first!r}")
    block = "".join(f"#define {k} {v}\n" for k, v in (defines or {}).items())
    return f"{first}\n{block}#line 2\n{rest}"


_LINE_RE = re.compile(r"^\s*\d+:(\d+)\(\d+\)|^\s*ERROR:\s*\d+:(\d+)|^\s*\d+\((\d+)\)", re.MULTILINE)


def _shader_error(err: Exception, files: dict[str, str]) -> ShaderError:
    """Turn a moderngl compile/link error into one naming the file and quoting the line."""
    text = str(err)
    kind = "fragment" if "fragment_shader" in text or "GL_FRAGMENT_SHADER" in text else "vertex"
    name = next((n for n in files if n.endswith(".frag" if kind == "fragment" else ".vert")), "?")
    m = _LINE_RE.search(text.split("\n", 3)[-1] if "\n" in text else text) or _LINE_RE.search(text)
    detail = next(
        (ln.strip() for ln in text.splitlines() if "error" in ln.lower() and ":" in ln),
        text.strip(),
    )
    if m:
        line = int(next(g for g in m.groups() if g))
        lines = files.get(name, "").splitlines()
        if len(lines) > 1 and lines[1] == "#line 2":
            del lines[1]  # the marker load_shader_source adds: back to the file's numbering
        quoted = lines[line - 1].strip() if 0 < line <= len(lines) else "?"
        return ShaderError(f"shaders/{name}:{line}: {detail} -- `{quoted}`")
    return ShaderError(f"shaders/{name}: {detail}")


def _program(ctx, vert: str, frag: str, defines: dict[str, object]):
    files = {vert: load_shader_source(vert), frag: load_shader_source(frag)}
    try:
        return ctx.program(
            vertex_shader=load_shader_source(vert, defines),
            fragment_shader=load_shader_source(frag, defines),
        )
    except Exception as e:  # noqa: BLE001 - moderngl.Error
        raise _shader_error(e, files) from None


def _gl_limit(ctx, key: str) -> int:
    v = ctx.info.get(key)
    if isinstance(v, tuple):
        return int(min(v))
    return int(v) if v else 1 << 30


def _check_gl(ctx, where: str) -> None:
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise RuntimeError(f"OpenGL error {err} {where}")
