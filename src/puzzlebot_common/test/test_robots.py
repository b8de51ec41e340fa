import pytest

from puzzlebot_common.errors import ConfigError
from puzzlebot_common.robots import parse_robot_list, robot_names


def test_parses_list_in_order_with_defaults():
    specs = parse_robot_list({"robots": [{"name": "pz2"}, {"name": "pz1", "pilot": True}, "pz3"]})
    assert robot_names(specs) == ["pz2", "pz1", "pz3"]
    assert specs[1].pilot and not specs[0].pilot
    assert specs[0].vicon_topic == "/vicon/pz2/pz2"


def test_mocap_subject_used_for_vicon_topic():
    spec = parse_robot_list([{"name": "front", "mocap": "p21", "ip_octet": 21}])[0]
    assert spec.vicon_topic == "/vicon/p21/p21"
    assert spec.ip_octet == 21


@pytest.mark.parametrize("data, fragment", [
    ([], "empty"),
    ("pz1", "expected a list"),
    ({"robot": []}, "expected a list"),
    ([{"pilot": True}], "missing 'name'"),
    ([{"name": "1abc"}], "robots[0].name"),
    ([{"name": "pz1"}, {"name": "pz1"}], "duplicate name"),
    ([{"name": "pz1", "pilot": "yes"}], "robots[0].pilot"),
    ([{"name": "pz1", "colour": "red"}], "unknown key"),
    ([{"name": "a", "ip_octet": 300}], "ip_octet"),
    ([{"name": "a", "ip_octet": 5}, {"name": "b", "ip_octet": 5}], "duplicate ip_octet"),
    ([{"name": "a", "mocap": "m"}, {"name": "b", "mocap": "m"}], "duplicate mocap subject"),
    ([42], "robots[0]"),
])
def test_malformed_lists_name_the_problem(data, fragment):
    with pytest.raises(ConfigError) as e:
        parse_robot_list(data)
    assert fragment in str(e.value)
