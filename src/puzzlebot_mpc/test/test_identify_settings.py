import math
import os
from dataclasses import asdict

import pytest

from puzzlebot_common.config import load_yaml
from puzzlebot_common.errors import ConfigError
from puzzlebot_mpc.identify import IdentifySettings

CONFIG = os.path.join(os.path.dirname(__file__), "..", "config", "identify.yaml")


def test_shipped_config_holds_the_defaults():
    """config/identify.yaml documents the defaults: it must not drift from the code."""
    assert asdict(IdentifySettings.from_dict(load_yaml(CONFIG))) == asdict(IdentifySettings())
    assert set(load_yaml(CONFIG)["identify"]) == set(asdict(IdentifySettings()))


@pytest.mark.parametrize("data, fragment", [
    ({"cv_folds": 1}, "cv_folds: must be >= 2"),
    ({"horizon_s": 0.0}, "horizon_s: must be > 0"),
    ({"grid_dt_s": 0.5}, "grid_dt_s (0.5) must be <= window_stride_s"),
    ({"residual_lags": 2.5}, "expected an integer"),
    ({"margin": 0.1}, "unknown key(s) margin"),
])
def test_bad_settings(data, fragment):
    with pytest.raises(ConfigError) as e:
        IdentifySettings.from_dict({"identify": data}, where="cfg.yaml")
    assert fragment in str(e.value)


def test_parameters_at_a_search_bound_are_flagged():
    from puzzlebot_common.effects import NOMINAL
    from puzzlebot_mpc.identify import core, fit

    params = dict(NOMINAL, delay_s=fit.PARAM_SPECS["delay_s"].upper, tau_v_s=0.0, tau_w_s=0.1, a_v=math.inf)
    sel = fit.Selection(["input_delay", "velocity_lag", "accel_limit"], [params], [], [], None, None,
                        shared=["input_delay", "velocity_lag", "accel_limit"])
    warnings = core.bound_warnings(sel, ["pz1"])
    assert len(warnings) == 1 and "input_delay.delay_s = 0.5 (all robots) is at the bound" in warnings[0]
