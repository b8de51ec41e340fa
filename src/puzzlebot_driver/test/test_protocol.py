import pytest

from puzzlebot_driver.protocol import ProtocolError, format_pwm, ip_last_octet, parse_pwm


@pytest.mark.parametrize("left, right, line", [(0, 0, b"0000,0000\n"), (120, -45, b"0120,-045\n"),
                                               (-250, 250, b"-250,0250\n")])
def test_format_matches_the_firmware_line(left, right, line):
    assert format_pwm(left, right) == line
    assert parse_pwm(line) == (left, right)


def test_round_trip_over_the_whole_range():
    for left in range(-250, 251, 7):
        for right in (-250, -1, 0, 1, 250):
            assert parse_pwm(format_pwm(left, right)) == (left, right)


@pytest.mark.parametrize("left, right", [(251, 0), (0, -251), (1.5, 0), (True, 0)])
def test_format_rejects_out_of_range_or_non_integers(left, right):
    with pytest.raises(ProtocolError):
        format_pwm(left, right)


@pytest.mark.parametrize("line", [b"", b"garbage\n", b"12;13\n", b"0300,0000\n", b"\xff\xfe\n", b"1,2,3\n"])
def test_parse_rejects_garbage(line):
    with pytest.raises(ProtocolError):
        parse_pwm(line)


def test_ip_last_octet():
    assert ip_last_octet("192.168.0.21") == 21
    with pytest.raises(ProtocolError):
        ip_last_octet("not-an-ip")
