"""PWM server details that loopback timing cannot show: framing under partial sends."""

from puzzlebot_driver.link import PwmServer, _Conn


class SlowSocket:
    """Takes at most ``n`` bytes per send; records what went out."""

    def __init__(self, n):
        self.n = n
        self.out = b""

    def send(self, data):
        k = min(self.n, len(data))
        self.out += data[:k]
        return k


def test_partial_sends_keep_framing_and_drop_stale_lines():
    server = PwmServer({21: "p21"})
    sock = SlowSocket(4)
    server._conns["p21"] = _Conn(sock, "127.0.0.21")
    assert not server.send("p21", 100, 100)      # 4 of 10 bytes out
    assert not server.send("p21", 50, 50)        # finishes "0100,0100\n" partly, queues the newest
    assert not server.send("p21", -20, 30)       # older whole lines are dropped, only the newest kept
    sock.n = 1000
    assert server.send("p21", 7, 8)
    lines = sock.out.split(b"\n")[:-1]
    assert all(len(line) == 9 for line in lines), sock.out
    assert lines[0] == b"0100,0100"
    assert lines[-1] == b"0007,0008"


def test_not_connected_is_reported_not_fatal():
    server = PwmServer({21: "p21"})
    assert server.send("p21", 10, 10) is False
    assert server.send("ghost", 0, 0) is False
    assert server.link_info("p21").connected is False
