"""ProjectorModel near its singularities: clear warnings, finite values; ik's on_nadir is validated."""

import math

import numpy as np
import pytest


def test_near_singularities_warn_with_a_clear_message_and_stay_finite():
    import warnings

    from robocal.errors import SingularConfigurationError
    from robocal.rigs.projector.model import NEAR_NADIR_WARN, NearSingularityWarning, ProjectorModel

    m = ProjectorModel(H=2.9, d1=0.12, tilt_limit=math.radians(75))
    for fn in (m.spot, m.spot_from_chain, m.beam_range, m.spot_jacobian):
        with pytest.warns(NearSingularityWarning, match="beyond the tilt limit 75 deg"):
            out = fn([0.3, math.pi / 2 - 1e-8])  # 2.7e8 m away: a warning, not silence
        assert np.all(np.isfinite(out))
    with pytest.warns(NearSingularityWarning, match=r"85 deg at index \(1,\)"):
        m.spot([[0.3, 0.5], [0.3, math.radians(85)]])
    with pytest.warns(NearSingularityWarning, match="within 0.001 rad of the nadir"):
        rates = m.joint_rates([0.3, 1e-4], [0.1, 0.0])
    assert np.all(np.isfinite(rates))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # inside the working range: silent
        m.spot([[0.3, 0.5], [0.3, math.radians(74.9)]])
        m.joint_rates([0.3, 2 * NEAR_NADIR_WARN], [0.1, 0.0])
    # scalar input: no meaningless "index ()", and a hint about the angle unit
    with pytest.raises(SingularConfigurationError) as exc:
        m.spot([0.3, 2.0])
    assert "index ()" not in str(exc.value) and "degrees passed as rad?" in str(exc.value)
    with pytest.raises(SingularConfigurationError) as exc:
        m.joint_rates([0.3, 1e-8], [0.1, 0.0])
    assert "index ()" not in str(exc.value)


def test_ik_validates_on_nadir_without_a_nadir_point():
    from robocal.errors import InputError
    from robocal.rigs.projector.model import ProjectorModel

    with pytest.raises(InputError, match="on_nadir"):
        ProjectorModel(H=2.9).ik([1.0, 1.0], on_nadir="bogus")
