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


def test_a_new_connection_from_the_same_robot_replaces_the_old_one():
    """An ESP8266 that rebooted reconnects while its old connection still looks open."""
    import socket
    import time

    logs = []
    server = PwmServer({21: "p21"}, host="127.0.0.1", port=0, log=lambda level, text: logs.append(text)).start()
    try:
        old = socket.create_connection(("127.0.0.1", server.port), source_address=("127.0.0.21", 0))
        deadline = time.monotonic() + 2.0
        while not server.connected("p21") and time.monotonic() < deadline:
            time.sleep(0.01)
        new = socket.create_connection(("127.0.0.1", server.port), source_address=("127.0.0.21", 0))
        deadline = time.monotonic() + 2.0
        while server.link_info("p21").connects < 2 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert server.send("p21", 12, -34)
        new.settimeout(2.0)
        assert new.recv(100) == b"0012,-034\n"
        old.settimeout(2.0)
        assert old.recv(100) == b""                        # closed by the server
        assert any("replaced by a new connection" in text for text in logs)
    finally:
        server.stop()
        old.close()
        new.close()
