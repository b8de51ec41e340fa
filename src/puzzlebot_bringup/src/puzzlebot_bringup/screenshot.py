"""rviz under a virtual X server: start it, take a screenshot, read its log (no rospy).

Used by the rostest ``rviz_screenshot`` and the ``rviz_screenshot`` script::

    with VirtualDisplay(1200, 800) as display:          # Xvfb on a free display number
        with Rviz(config_path, display, log_path) as rviz:
            ...wait...
            image = display.grab()                       # PIL.Image of the whole screen
        problems = rviz_log_errors(log_path)

rviz (the Debian package) renders with Mesa's software OpenGL under Xvfb.
"""

import os
import signal
import subprocess
import time

#: Log lines that contain ERROR but are not a problem of the stack or its rviz configuration.
BENIGN_ERRORS = (
    # rviz asks rospack for the plugin export of 'media_export', a package Debian does not ship;
    # rviz's own media are found anyway.
    "[rospack] Error: no such package media_export",
    # ... and librospack's line that goes with it.
    "[librospack]: error while executing command",
)

X_LOCK = "/tmp/.X%d-lock"
X_SOCKET = "/tmp/.X11-unix/X%d"


class ScreenshotError(RuntimeError):
    """Xvfb or rviz could not be started or the screen could not be read."""


def free_display(first=90, last=400):
    """A display number with neither an X lock file nor a socket."""
    for n in range(first, last):
        if not os.path.exists(X_LOCK % n) and not os.path.exists(X_SOCKET % n):
            return n
    raise ScreenshotError("no free X display number in %d..%d" % (first, last))


def _stop(proc, timeout=10.0):
    if proc is None or proc.poll() is not None:
        return
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout)


class VirtualDisplay:
    """Xvfb on a free display number, for the lifetime of the ``with`` block."""

    def __init__(self, width=1200, height=800, depth=24, start_timeout=10.0):
        self.width, self.height, self.depth, self.start_timeout = width, height, depth, start_timeout
        self.number = None
        self.proc = None

    @property
    def name(self):
        return ":%d" % self.number

    def __enter__(self):
        for _attempt in range(5):        # another process may take the number between check and start
            self.number = free_display()
            self.proc = subprocess.Popen(["Xvfb", self.name, "-screen", "0", "%dx%dx%d" % (
                self.width, self.height, self.depth), "-nolisten", "tcp"], stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL)
            end = time.monotonic() + self.start_timeout
            while time.monotonic() < end and self.proc.poll() is None:
                if os.path.exists(X_SOCKET % self.number):
                    return self
                time.sleep(0.05)
            _stop(self.proc)
        raise ScreenshotError("Xvfb did not start (is the xvfb package installed?)")

    def __exit__(self, *exc):
        _stop(self.proc)

    def grab(self):
        """The whole screen as a PIL image."""
        from PIL import ImageGrab

        return ImageGrab.grab(xdisplay=self.name)


class Rviz:
    """rviz with ``config`` on ``display``; its stdout and stderr go to ``log_path``."""

    def __init__(self, config, display, log_path, extra_env=None):
        self.config, self.display, self.log_path = config, display, log_path
        self.env = dict(os.environ, DISPLAY=display.name, **(extra_env or {}))
        self.proc = None
        self._log = None

    def __enter__(self):
        if not os.path.isfile(self.config):
            raise ScreenshotError("rviz configuration %s does not exist" % self.config)
        self._log = open(self.log_path, "w")
        # a node name of its own: rostest names the test node after the test
        self.proc = subprocess.Popen(["rosrun", "rviz", "rviz", "-d", self.config,
                                      "__name:=rviz_xvfb%d" % self.display.number],
                                     stdout=self._log, stderr=subprocess.STDOUT, env=self.env)
        return self

    def running(self):
        return self.proc is not None and self.proc.poll() is None

    def __exit__(self, *exc):
        _stop(self.proc)
        self._log.close()


def rviz_log_errors(log_path):
    """ERROR lines of an rviz log (and fatal lines), without the known benign ones."""
    out = []
    with open(log_path, errors="replace") as f:
        for line in f:
            low = line.lower()
            if ("error" in low or "fatal" in low or "segmentation fault" in low) and not any(
                    b in line for b in BENIGN_ERRORS):
                out.append(line.rstrip())
    return out


def hue_pixels(image, box=None):
    """Counts of clearly blue, green, cyan, orange, red and yellow pixels (robot bodies, coupled
    pairs, seated anchors, pilots, decoupled and head-aligned pairs in the shipped colours), in
    ``box`` = (left, top, right, bottom) or the whole image. Dominance thresholds, not exact
    colours: lighting and transparency change the shades."""
    import numpy as np

    img = image.convert("RGB")
    if box is not None:
        img = img.crop(box)
    a = np.asarray(img, dtype=int)
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    return {"blue": int(((b > r + 60) & (b > g + 20)).sum()),
            "green": int(((g > r + 50) & (g > b + 30)).sum()),
            "cyan": int(((g > 150) & (b > 150) & (r < 100)).sum()),
            "orange": int(((r > g + 50) & (g > b + 40)).sum()),
            "red": int(((r > g + 80) & (r > b + 80) & (g < 100)).sum()),
            "yellow": int(((r > 180) & (g > 140) & (b < 80)).sum())}
