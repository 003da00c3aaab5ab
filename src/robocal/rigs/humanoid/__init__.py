"""NAO-class humanoid leg and camera calibration from foot checkerboards (seed 001)."""
