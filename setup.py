"""Build step pyproject.toml cannot state stably: the flow rig's optional C kernel.

Everything else about the package is in pyproject.toml. The extension is
``optional``: an install without a C compiler or Python's headers still
succeeds, and the flow rig then runs the same kernel through numba
(robocal.rigs.flow.kernel.kernel_backend). Written here rather than as
pyproject's ``[tool.setuptools.ext-modules]``, which setuptools still marks
experimental ("likely to change in future releases").
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("robocal.rigs.flow._flowc", sources=["src/robocal/rigs/flow/flowc.c"], optional=True)])
