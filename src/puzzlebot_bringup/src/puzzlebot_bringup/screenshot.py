"""rviz under a virtual X server: start it, take a screenshot, read its log (no rospy).

Used by the rostest ``rviz_screenshot`` and the ``rviz_screenshot`` script::

    with VirtualDisplay(1200, 800) as display:          # Xvfb on a free display number
        with Rviz(config_path, display, log_path) as rviz:
            ...wait...
            image = display.grab()                       # PIL.Image of the whole screen
        problems = rviz_log_errors(log_path)

rviz (the Debian package) renders with Mesa's software OpenGL under Xvfb.
``robots_in_view`` reads, from the pixels alone, how many robots a screenshot
of the shipped configuration shows and whether one is cut by the view's edge.
"""

import os
import signal
import subprocess
import time
from dataclasses import dataclass

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


def _masks(image, box=None):
    """Masks of robot bodies (blue robots, orange pilots), yellow (knobs) and the dark floor."""
    import numpy as np

    img = image.convert("RGB")
    if box is not None:
        img = img.crop(box)
    a = np.asarray(img, dtype=int)
    r, g, b = a[..., 0], a[..., 1], a[..., 2]
    body = ((b > r + 60) & (b > g + 20)) | ((r > g + 50) & (g > b + 40))      # blue robots, orange pilots
    knob = (r > 180) & (g > 140) & (b < 80)                                    # the yellow side knobs
    background = (a.max(axis=2) - a.min(axis=2) < 20) & (a.max(axis=2) < 120)  # dark grey floor and grid
    return body, knob, background


@dataclass
class RobotsInView:
    """What a screenshot shows of the robots (``robots_in_view``)."""

    knobs: int             # robots seen: each robot's knob, a yellow disc on its left side next to its body
    cut: int               # robot bodies (blue or orange regions) touching the view's edge
    body_pixels: int


def robots_in_view(image, box=None, min_knob=20, min_fill=0.4, max_aspect=2.5, min_body=200, reach=3,
                   min_outside=0.25):
    """Count the robots in a screenshot of the shipped rviz view (``box``: the 3D view, (left, top,
    right, bottom); None: the whole image), from the pixels.

    Robots are counted by their knobs: every robot model (RobotModel, the URDF's yellow knob) has one
    on its left side, sticking out of the body, so it shows from above even when robots are coupled
    and their bodies touch. A knob is a compact yellow region (at least ``min_knob`` px, filling at
    least ``min_fill`` of its bounding box, sides within ``max_aspect`` of each other: not a pair's
    yellow outline, not a letter of the legend) within ``reach`` px of a robot body (a blue or orange
    region of at least ``min_body`` px) and sticking out of it: at least ``min_outside`` of the pixels
    around it are the dark floor (not a yellow pair line drawn on a body). ``cut``: robot bodies touching the view's edge (a robot
    partly out of the picture). Pixel sizes are those of the shipped view (1400 px/m).
    """
    import numpy as np
    from scipy import ndimage

    body, knob, background = _masks(image, box)
    labels, n = ndimage.label(body)
    sizes = ndimage.sum(body, labels, range(1, n + 1))
    bodies = np.isin(labels, [k + 1 for k, size in enumerate(sizes) if size >= min_body])
    near_body = ndimage.binary_dilation(bodies, iterations=reach)
    knobs = 0
    klabels, kn = ndimage.label(knob)
    for k, sl in enumerate(ndimage.find_objects(klabels), start=1):
        region = klabels[sl] == k
        h, w = region.shape
        area = int(region.sum())
        if area < min_knob or area < min_fill * h * w or max(h, w) > max_aspect * min(h, w):
            continue
        grown = tuple(slice(max(0, d.start - 2), d.stop + 2) for d in sl)
        inside = klabels[grown] == k
        ring = ndimage.binary_dilation(inside, iterations=2) & ~inside
        if near_body[grown][ring].any() and background[grown][ring].mean() >= min_outside:
            knobs += 1
    edge = np.zeros_like(bodies)
    edge[0, :] = edge[-1, :] = edge[:, 0] = edge[:, -1] = True
    cut = len(set(np.unique(labels[edge & bodies])) - {0})
    return RobotsInView(knobs, cut, int(bodies.sum()))
