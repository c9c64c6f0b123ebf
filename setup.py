"""The one compiled part: the pose stage's C kernel (tactile_manip/perception/_pose_kernel.c), optional.

Everything else is in pyproject.toml. The kernel is plain C (no Python headers) loaded with ctypes; where it
cannot be built (no C compiler) the install still succeeds, with a warning, and the pose stage runs its numpy
path (the same angles, about 3x the post-processing time): ``tactile-manip --version`` says which
one runs.
"""

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

# -fno-trapping-math lets the compiler vectorise the branch-free selects of the moments; -ffp-contract=fast
# fuses multiply-adds (ISO C modes turn it off). Neither changes what the kernel computes beyond rounding.
UNIX_FLAGS = ["-O3", "-std=c11", "-ffp-contract=fast", "-fno-trapping-math"]


class BuildKernel(build_ext):
    """build_ext with the kernel's optimisation flags for gcc and clang (MSVC keeps its defaults)."""

    def build_extensions(self) -> None:
        if self.compiler.compiler_type == "unix":
            for ext in self.extensions:
                ext.extra_compile_args = UNIX_FLAGS + list(ext.extra_compile_args or [])
        super().build_extensions()


setup(
    ext_modules=[Extension("tactile_manip.perception._pose_kernel", ["tactile_manip/perception/_pose_kernel.c"],
                           optional=True)],
    cmdclass={"build_ext": BuildKernel},
)
