"""Build step of the install: the C libraries, the LD_PRELOAD library behind ``rollcam run`` and the renderer's
background shader (the rest is in pyproject.toml)."""

import shutil

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CompileError

LIBRARY = "rollcam.emu.preload.librollcam_preload"
SHADER = "rollcam.sim.render.librollcam_shade"
PLAIN = (LIBRARY, SHADER)
"""Libraries built as plain shared objects (no Python ABI tag or init function): loaded by path, not imported."""


class BuildPlain(build_ext):
    """Builds the libraries as plain shared objects (programs preload the one, the renderer loads the other, by
    path), failing with the compiler's name when there is none."""

    def build_extensions(self) -> None:
        cc = self.compiler.compiler_so[0] if getattr(self.compiler, "compiler_so", None) else "cc"
        if shutil.which(cc) is None:
            raise CompileError(f"rollcam: building its C libraries (rollcam run, the renderer) needs a C compiler; "
                               f"{cc!r} was not found: install one (Debian: apt-get install gcc) or set CC")
        super().build_extensions()

    def get_ext_filename(self, fullname: str) -> str:
        if fullname.rsplit(".", 1)[-1] in {name.rsplit(".", 1)[-1] for name in PLAIN}:  # the full or the last name
            return fullname.replace(".", "/") + ".so"
        return super().get_ext_filename(fullname)

    def get_export_symbols(self, ext: Extension) -> list[str]:
        return [] if ext.name in PLAIN else super().get_export_symbols(ext)


setup(
    ext_modules=[Extension(LIBRARY, sources=["emu/preload/rollcam_preload.c"],
                           # -Wno-nonnull-compare: the interposed calls check the pointers libc declares nonnull
                           extra_compile_args=["-O2", "-U_FORTIFY_SOURCE", "-Wall", "-Wextra", "-Werror",
                                               "-Wno-nonnull-compare"],
                           extra_link_args=["-ldl", "-lpthread"]),
                 # -O3 and -fopenmp-simd (the pragma only, no OpenMP runtime) vectorise the pixel loop; no
                 # -ffast-math and no FMA contraction, so every CPU clone computes the same image (see the source).
                 Extension(SHADER, sources=["sim/render/rollcam_shade.c"],
                           extra_compile_args=["-O3", "-fopenmp-simd", "-ffp-contract=off", "-fno-math-errno",
                                               "-fno-trapping-math"],
                           extra_link_args=["-lm"])],
    cmdclass={"build_ext": BuildPlain},
)
