"""A feedforward's own share of e2 over the noise floor: sqrt(e2^2 - floor^2), never NaN."""

import math

import pytest

from flexff.cosim.metrics import own_share


def test_own_share_is_the_root_of_the_difference_of_squares():
    assert own_share(5.0, 3.0) == pytest.approx(4.0, rel=1e-12)
    assert own_share(2.5e-6, 0.0) == 2.5e-6  # no floor: all of e2 is the feedforward's
    assert own_share(1.0 + 1e-12, 1.0) == pytest.approx(math.sqrt(2e-12), rel=1e-3)


def test_at_or_below_the_floor_the_own_share_is_zero():
    assert own_share(0.93e-6, 0.93e-6) == 0.0
    assert own_share(0.9e-6, 0.93e-6) == 0.0  # noise alone can land under the floor


@pytest.mark.parametrize("e2, floor", [(math.nan, 1.0), (1.0, math.inf), (-1.0, 0.0),
                                       (1.0, -0.5)])
def test_a_meaningless_e2_or_floor_is_refused(e2, floor):
    with pytest.raises(ValueError, match="must be finite and not negative"):
        own_share(e2, floor)
