"""Build step of the install: the LD_PRELOAD library behind ``rollcam run`` (the rest is in pyproject.toml)."""

import shutil

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CompileError

LIBRARY = "rollcam.emu.preload.librollcam_preload"


class BuildPreload(build_ext):
    """Builds the preload library as a plain shared object (no Python ABI tag: programs preload it by path),
    failing with the compiler's name when there is none."""

    def build_extensions(self) -> None:
        cc = self.compiler.compiler_so[0] if getattr(self.compiler, "compiler_so", None) else "cc"
        if shutil.which(cc) is None:
            raise CompileError(f"rollcam: building the preload library (rollcam run) needs a C compiler; {cc!r} "
                               "was not found: install one (Debian: apt-get install gcc) or set CC")
        super().build_extensions()

    def get_ext_filename(self, fullname: str) -> str:
        if fullname.rsplit(".", 1)[-1] == LIBRARY.rsplit(".", 1)[-1]:  # called with the full or the last name
            return fullname.replace(".", "/") + ".so"
        return super().get_ext_filename(fullname)

    def get_export_symbols(self, ext: Extension) -> list[str]:
        return [] if ext.name == LIBRARY else super().get_export_symbols(ext)


setup(
    ext_modules=[Extension(LIBRARY, sources=["emu/preload/rollcam_preload.c"],
                           extra_compile_args=["-O2", "-U_FORTIFY_SOURCE", "-Wno-nonnull-compare"],
                           extra_link_args=["-ldl", "-lpthread"])],
    cmdclass={"build_ext": BuildPreload},
)
