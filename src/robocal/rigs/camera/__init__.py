"""The ``camera`` rig: intrinsic calibration from images of a target, the first step of every camera rig.

Built on the core camera package (:mod:`robocal.camera`: targets, detection,
``calibrate_intrinsics``, camera files); this package is the workflow around
it (images and a target in; result, report and camera files out). See
``docs/rigs/camera.md``.
"""
