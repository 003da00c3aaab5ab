"""The rigs: one complete calibration workflow per published method.

Each rig builds on the core (``robocal.geometry``, ``kinematics``, ``camera``,
``estimation``, ``io``, ``report``, ``cli``) and registers its command line
through the ``robocal.rigs`` entry-point group. Rigs never import each other.
"""
