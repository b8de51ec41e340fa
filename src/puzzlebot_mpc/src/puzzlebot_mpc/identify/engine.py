"""The error metric: open-loop prediction windows, integrated fast.

A window starts at a measured pose (time ts) and ends at the measured pose
nearest ts + H (time te). The model's prediction of the pose at te starts
from the measured pose at ts with the actuator state that the commands of the
previous ``history_s`` seconds produce, and integrates the recorded commands.

Every window of a robot sees the same actuator velocity signal (the actuator
state depends on the commands only, not on the pose), so the velocities are
computed once on a uniform grid (``effects.actuator_velocities``, started in
steady state ``history_s`` before the first window) and every window is two
look-ups in cumulative integrals: the heading change
``Theta(te) - Theta(ts)`` and the displacement
``exp(i (yaw_s - offset - Theta(ts))) (C(te) - C(ts))`` with
``C(t) = integral of v exp(i Theta)``. This is the same model as
``effects.predict`` (tests compare them) at a cost independent of H.
"""

from dataclasses import dataclass, field, replace

import numpy as np

from puzzlebot_common.geometry import wrap_angle
from puzzlebot_common.effects import actuator_velocities, command_pieces
from puzzlebot_mpc.identify.data import DataError


PIECES_CACHE = 8      # command-piece structures kept per window set (one per recent delay value)
PATH_CACHE = 4        # integrated turn-rate signals kept per window set (``_path``), most recent first
POSITION_CACHE = 2    # ... and per turn-rate signal, integrated speed signals
SERIES_LIMIT = 0.02   # rad: below this half-angle sin(x)/x is taken as 1 - x^2/6


@dataclass
class Windows:
    """Prediction windows of one robot, with their integration grid."""

    robot: str
    ts: np.ndarray        # start times [s]
    te: np.ndarray        # end times [s]
    p_start: np.ndarray   # measured positions (complex x + iy) at ts
    p_end: np.ndarray     # ... and at te
    yaw_start: np.ndarray
    yaw_end: np.ndarray
    g0: float             # integration grid start [s]
    dt: float
    n: int                # grid intervals
    ks: np.ndarray        # grid interval holding ts, and the fraction of it before ts
    fs: np.ndarray
    ke: np.ndarray
    fe: np.ndarray
    cache: dict = field(default_factory=dict, repr=False)   # delay -> command pieces of the grid, and
                                                             # ("memo", delay) -> their component memo
    paths: list = field(default_factory=list, repr=False)   # recent integrations of the grid (_path)
    part: np.ndarray = None   # cross-validation part (fold) of each window
    edges: np.ndarray = None  # time edges [s] of the parts (len = parts + 1)

    def __len__(self):
        return int(self.ts.size)

    def fit_mask(self, k):
        """Windows that may be fitted when part k is held out: none of them overlaps part k in time."""
        return (self.te <= self.edges[k]) | (self.ts >= self.edges[k + 1])


def nearest_samples(t, wanted, tol):
    """Index of the pose sample nearest each wanted time, and a mask of those within tol."""
    if t.size < 2 or wanted.size == 0:
        j = np.zeros(wanted.size, int)
        return j, np.abs(t[j] - wanted) <= tol if t.size else np.zeros(wanted.size, bool)
    j = np.clip(np.searchsorted(t, wanted), 1, t.size - 1)
    j = np.where((wanted - t[j - 1]) <= (t[j] - wanted), j - 1, j)
    return j, np.abs(t[j] - wanted) <= tol


def median_period(r):
    return float(np.median(np.diff(r.t))) if r.t.size > 1 else 0.0


def usable_start(r, history_s):
    """Earliest window start: the record's start plus the command history."""
    return max(float(r.t[0]), float(r.cmd_t[0])) + history_s


def make_windows(r, t_from, t_to, horizon, stride, settings):
    """Windows of about ``horizon`` s starting every ``stride`` s, inside [t_from, t_to]."""
    tol = settings.pose_tolerance * median_period(r)
    count = int(np.floor((t_to - horizon - t_from) / stride + 1e-9)) + 1 if t_to - horizon >= t_from else 0
    i0, ok = nearest_samples(r.t, t_from + stride * np.arange(count), tol)
    i0 = np.unique(i0[ok])
    i0 = i0[r.t[i0] >= t_from]
    i1, ok = nearest_samples(r.t, r.t[i0] + horizon, tol)
    keep = ok & (i1 > i0) & (r.t[i1] <= t_to)
    i0, i1 = i0[keep], i1[keep]
    ts, te = r.t[i0], r.t[i1]
    dt = settings.grid_dt_s
    g0 = (float(ts.min()) if ts.size else t_from) - settings.history_s
    n = int(np.ceil(((float(te.max()) if te.size else t_to) - g0) / dt)) + 1
    xs, xe = (ts - g0) / dt, (te - g0) / dt
    ks, ke = np.floor(xs).astype(int), np.floor(xe).astype(int)
    return Windows(robot=r.name, ts=ts, te=te, p_start=r.x[i0] + 1j * r.y[i0], p_end=r.x[i1] + 1j * r.y[i1],
                   yaw_start=r.yaw[i0], yaw_end=r.yaw[i1], g0=g0, dt=dt, n=n,
                   ks=ks, fs=xs - ks, ke=ke, fe=xe - ke)


def subset(w, mask):
    """The windows selected by a boolean mask (same grid)."""
    per_window = ("ts", "te", "p_start", "p_end", "yaw_start", "yaw_end", "ks", "fs", "ke", "fe")
    extra = {"part": w.part[mask]} if w.part is not None else {}
    return replace(w, cache={}, paths=[], **{k: getattr(w, k)[mask] for k in per_window}, **extra)


def robot_windows(r, settings):
    """Every prediction window of a robot's usable record, each labelled with its cross-validation
    part: the record from its usable start cut into ``cv_folds`` equal parts in time. DataError if
    a part has no window (too short or too sparse)."""
    t0, t1 = usable_start(r, settings.history_s), float(r.t[-1])
    w = make_windows(r, t0, t1, settings.horizon_s, settings.window_stride_s, settings)
    k = settings.cv_folds
    edges = t0 + (t1 - t0) * np.arange(k + 1) / k
    w.edges = edges
    w.part = np.clip(np.searchsorted(edges, w.ts, side="right") - 1, 0, k - 1)
    counts = np.bincount(w.part, minlength=k) if len(w) else np.zeros(k, int)
    if np.any(counts == 0) or any(not np.any(w.fit_mask(j)) for j in range(k)):
        raise DataError("robot %s: the record is too short or too sparse for %d cross-validation parts (%.1f s of "
                        "poses from t=%.1f s, first command at t=%.1f s); each part needs windows of %.1f s with "
                        "pose samples at both ends, after %.1f s of command history"
                        % (r.name, k, r.duration, r.t[0], r.cmd_t[0], settings.horizon_s, settings.history_s))
    return w


def _pieces(r, w, delay):
    """The command pieces of a window set's grid for a delay, cached (fits vary the other
    parameters far more often than the delay)."""
    cache = w.cache
    if delay not in cache:
        if len(cache) >= 2 * PIECES_CACHE:       # pieces and their component memos
            old = next(k for k in cache if not isinstance(k, tuple))
            cache.pop(old)
            cache.pop(("memo", old), None)
        cache[delay] = command_pieces(r.cmd_t, delay, w.g0, w.dt, w.n)
    return cache[delay]


def _same(a, b):
    """Bitwise equality of two float arrays (what makes a cached integration reusable exactly)."""
    return a is b or (a.shape == b.shape and bool((a.view(np.int64) == b.view(np.int64)).all()))


def _cached(entries, key, size, compute):
    """The value stored with an array equal to ``key`` (a float array) in ``entries`` (a list of
    (sum, key, value), most recent first), or ``compute()``, stored first (at most ``size`` entries
    kept). The sums tell most different keys apart at the cost of one sum."""
    total = float(np.sum(key))
    for s, k, value in entries:
        if (s == total or s != s) and _same(k, key):
            return value
    value = compute()
    entries.insert(0, (total, key, value))
    del entries[size:]
    return value


def _heading(om, dt):
    """The heading integrated on the grid from the turn rate ``om`` [rad/s] per interval of dt [s]:
    the heading change per interval ``dth`` [rad], the cumulative heading ``theta`` at the grid
    points (0 at the first), and the unit step of each interval (chord of the exact arc per metre
    of path, as a complex direction)."""
    dth = om * dt
    theta = np.concatenate([[0.0], np.cumsum(dth)])
    half = 0.5 * dth
    # exact arc per interval: chord = v dt sin(half) / half along theta + half; the series of
    # sin(x)/x to x^2 is exact to 1e-9 for |x| < 0.02 (2 rad/s at dt = 0.01 s gives 0.01)
    chord = 1.0 - half * half / 6.0
    big = np.abs(half) >= SERIES_LIMIT
    if big.any():
        chord[big] = np.sin(half[big]) / half[big]
    return dth, theta, chord, np.exp(1j * (theta[:-1] + half))


def _path(w, v, om):
    """The grid integration of the velocities (v [m/s], om [rad/s], one value per grid interval):
    per interval the heading change ``dth`` [rad] and the displacement ``dz`` [m] (complex, in the
    frame of the grid's start), each followed by a 0 for the look-ups, and at the grid points the
    cumulative heading ``theta`` and displacement ``c``.

    Kept per window set (the last PATH_CACHE turn-rate signals, each with its last POSITION_CACHE
    speed signals): a fit that varies only a speed parameter reuses the heading and its complex
    exponential (the costly part), one that varies only the heading offset reuses everything.
    Reused for bitwise equal signals only, with the same arithmetic: the results are the same."""
    def heading():
        dth, theta, chord, step = _heading(om, w.dt)
        return np.append(dth, 0.0), theta, chord, step, []

    dth, theta, chord, step, positions = _cached(w.paths, om, PATH_CACHE, heading)

    def position():
        dz = v * w.dt * chord * step
        return np.append(dz, 0.0), np.concatenate([[0.0], np.cumsum(dz)])

    dz, c = _cached(positions, v, POSITION_CACHE, position)
    return dth, theta, dz, c


def predict(params, r, w):
    """Predicted measured pose at each window's end: (complex position, yaw)."""
    pieces = _pieces(r, w, params["delay_s"])
    memo = w.cache.setdefault(("memo", params["delay_s"]), {})
    v, om = actuator_velocities(params, r.cmd_t, r.cmd_v, r.cmd_w, w.g0, w.dt, w.n, pieces=pieces,
                                t_start=r.t_start, memo=memo)
    dth, theta, dz, c = _path(w, v, om)
    th_s = theta[w.ks] + w.fs * dth[w.ks]
    th_e = theta[w.ke] + w.fe * dth[w.ke]
    c_s = c[w.ks] + w.fs * dz[w.ks]
    c_e = c[w.ke] + w.fe * dz[w.ke]
    yaw = w.yaw_start + (th_e - th_s)
    pos = w.p_start + np.exp(1j * (w.yaw_start - params["offset_rad"] - th_s)) * (c_e - c_s)
    return pos, yaw


def errors(params, r, w):
    """Measured minus predicted end pose: (complex position error [m], wrapped yaw error [rad])."""
    pos, yaw = predict(params, r, w)
    return w.p_end - pos, wrap_angle(w.yaw_end - yaw)


@dataclass
class Metric:
    rmse_pos_m: float
    rmse_yaw_rad: float
    n: int

    def as_dict(self):
        return {"rmse_pos_m": self.rmse_pos_m, "rmse_yaw_rad": self.rmse_yaw_rad}


def metric(errs):
    """Pooled RMSE of a list of (position error, yaw error) arrays (a robot's, or one per robot)."""
    ep = np.concatenate([e[0] for e in errs]) if errs else np.zeros(0)
    ey = np.concatenate([e[1] for e in errs]) if errs else np.zeros(0)
    if ep.size == 0:
        return Metric(float("nan"), float("nan"), 0)
    return Metric(float(np.sqrt(np.mean(np.abs(ep) ** 2))), float(np.sqrt(np.mean(ey ** 2))), int(ep.size))


def command_at(r, times):
    """(v, w) command in force at each time (issued at or before it; zero before the first)."""
    i = np.searchsorted(r.cmd_t, times, side="right") - 1
    safe = np.maximum(i, 0)
    return np.where(i >= 0, r.cmd_v[safe], 0.0), np.where(i >= 0, r.cmd_w[safe], 0.0)
