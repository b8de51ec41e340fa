"""The soft anchor's linkage geometry and the barb restoring-torque law.

The soft anchor is simulated as a rigid three-bar linkage (paper, section
"Simulation Experiments"): the middle bar is fixed to the anchor base, the
two side bars (barbs) hang on revolute joints at the head and point back
toward the base at ``barb_angle`` (phi_0) from the bar. Each barb's joint is
driven back to rest by a velocity servo whose torque limit is updated every
step from the measured force profile, so the barb yields exactly when the
load exceeds what the real beam would carry at that displacement:

* pushed in (the opening's lip edges slide along the barbs' outer faces):
  the barbs fold (phi < phi_0) -- forward profile;
* pulled back (the lips' inner faces press on the barb tips): the barbs flare
  (phi > phi_0) -- backward profile. Past the end of the backward profile
  (about perpendicular, 5 mm) the beam snaps through: the torque drops to
  ``barb_post_snap_ratio`` times its value there (never below the floor) and
  stays there while the barb flips forward, which is how an anchor comes out.
  The ratio is not measured: the rig's force drop near 4.7 mm is the probe
  slipping off the tips, which the slits prevent on the robot (facts.md), so
  the beam keeps a share of its load (docs/sim.md, "The anchor model and how it works").

Mapping from beam force to joint torque. The profile F(d) is the force on
the whole anchor (both barbs) against the probe displacement d, measured with
a probe shaped like the opening's lips. Quasi-statically, with frictionless
contacts (the measured profile already contains the real friction), a barb at
angle phi touches the probe at a point P with contact normal m (the force on
the barb, pointing from the probe into the barb) and

    d(phi)   = probe travel from first contact to angle phi
    tau(phi) = F(d(phi)) / 2 * lambda(phi),
    lambda   = |(P - H) x m| / |m_x|   (torque per newton of probe force, H = hinge)

forward: P slides along the barb's outer face, lambda = s / sin(phi) with s
the contact's distance from the hinge, then over the rounded tip;
backward: P is the rounded tip's extreme point, lambda = b sin(phi) and
d = b (cos(phi_0) - cos(phi)).
``BarbTorqueMap`` tabulates tau against the joint angle q = phi - phi_0.

Frames: anchor frame at the centre of the anchor base, x toward the robot it
belongs to (its head points to -x), y to the left, z up. Lengths in metres.
"""

import bisect
import math

import numpy as np


class AnchorGeometry:
    """Points of the anchor linkage in the anchor frame (left barb; mirror y for the right)."""

    def __init__(self, a):
        self.a = a
        self.head_tip_x = -a.length
        self.head_centre_x = -a.length + a.head_width / 2.0
        self.hinge = (self.head_centre_x + a.hinge_back, a.head_width / 2.0 - a.hinge_back)

    def barb_axes(self, phi):
        """Unit vector along the left barb (hinge -> tip) and its outward normal."""
        c, s = math.cos(phi), math.sin(phi)
        return np.array([c, s]), np.array([-s, c])

    def tip_centre(self, phi):
        """Centre of the left barb's rounded tip at barb angle ``phi``."""
        u, _ = self.barb_axes(phi)
        return np.array(self.hinge) + self.a.barb_length * u

    def half_width(self):
        """Largest |y| of the anchor at rest (barb tips included)."""
        return max(self.tip_centre(self.a.barb_angle)[1] + self.a.barb_tip_radius, self.a.head_width / 2)


def _cross(a, b):
    return a[0] * b[1] - a[1] * b[0]


class BarbTorqueMap:
    """Torque limit of a barb joint against its angle, from the force profiles.

    ``mouth_width`` and ``lip_radius`` describe the lips (and the force rig's
    probe, which copies them): two plates with a gap of ``mouth_width``
    between their rounded inner ends of radius ``lip_radius``.
    """

    def __init__(self, a, mouth_width, lip_radius, samples=400):
        self.a = a
        self.geometry = g = AnchorGeometry(a)
        hinge = np.array(g.hinge)
        hx, hy = g.hinge
        b, t, r_t, phi0 = a.barb_length, a.barb_thickness, a.barb_tip_radius, a.barb_angle
        r_e = lip_radius
        y_c = mouth_width / 2.0 + r_e
        fwd_mm, fwd_n = np.array(a.forward_profile_mm) * 1e-3, np.array(a.forward_profile_n)
        bwd_mm, bwd_n = np.array(a.backward_profile_mm) * 1e-3, np.array(a.backward_profile_n)

        # forward (fold): the lip edge (circle) slides +x along the barb's outer face, then over the
        # rounded tip; for each angle the probe stops at its first contact (smallest x)
        phis, xs, lams = [], [], []
        for phi in np.linspace(phi0, a.barb_fold_limit, samples):
            u, n = g.barb_axes(phi)
            candidates = []
            x_f = hx + ((y_c - hy) * u[0] - t / 2 - r_e) / u[1]
            s_f = (x_f - hx) * u[0] + (y_c - hy) * u[1]
            if 0.0 <= s_f <= b:
                candidates.append((x_f, s_f / u[1]))
            tip = hinge + b * u
            dy = y_c - tip[1]
            reach = r_e + r_t
            if abs(dy) < reach:
                x_t = tip[0] - math.sqrt(reach * reach - dy * dy)
                m = (tip - np.array([x_t, y_c])) / reach
                candidates.append((x_t, abs(_cross(tip - hinge, m)) / max(m[0], 1e-9)))
            if not candidates:
                break                                  # the tip has passed the lip edge
            x_c, lam = min(candidates)
            phis.append(phi)
            xs.append(x_c)
            lams.append(lam)
        d = np.array(xs) - xs[0]
        self.forward_first_contact_x = float(xs[0])     # lip-edge centre x at first contact (anchor frame)
        self.forward_pass_mm = 1e3 * d[-1]              # probe travel until the tips pass the lips
        tau_f = 0.5 * np.interp(d, fwd_mm, fwd_n) * np.array(lams)
        q_f = np.array(phis)[::-1] - phi0
        tau_f = tau_f[::-1]

        # backward (flare): the lip's flat inner face pushes the rounded tip at its extreme point;
        # up to the end of the profile (at most perpendicular)
        phis_b = np.linspace(phi0, math.pi / 2, samples)
        d_b = b * (math.cos(phi0) - np.cos(phis_b))
        lam_b = b * np.sin(phis_b)
        keep = d_b <= bwd_mm[-1] + 1e-12
        self.snap_angle = float(phis_b[keep][-1])       # barb angle where the beam snaps through
        self.snap_mm = 1e3 * float(d_b[keep][-1])
        tau_b = 0.5 * np.interp(d_b[keep], bwd_mm, bwd_n) * lam_b[keep]
        q_b = phis_b[keep] - phi0

        floor = a.barb_min_torque
        q_snap = q_b[-1] + 1e-4
        self.post_snap_torque = max(a.barb_post_snap_ratio * float(tau_b[-1]), floor)
        self.q = np.concatenate([q_f, q_b[1:], [q_snap]])
        self.tau = np.maximum(np.concatenate([tau_f, tau_b[1:], [self.post_snap_torque]]), floor)
        self.rest_lateral = float(hy + b * math.sin(phi0))
        self._q_list = [float(v) for v in self.q]
        self._tau_list = [float(v) for v in self.tau]   # tip centre's distance from the bar axis

    def torque_at(self, q):
        """``max_torque`` for one angle, without numpy (called for every barb at every step)."""
        qs = self._q_list
        if q <= qs[0]:
            return self._tau_list[0]
        if q >= qs[-1]:
            return self.post_snap_torque
        i = bisect.bisect_right(qs, q)
        q0, q1 = qs[i - 1], qs[i]
        t0, t1 = self._tau_list[i - 1], self._tau_list[i]
        return t0 + (t1 - t0) * (q - q0) / (q1 - q0)

    def max_torque(self, q):
        """Torque limit [N m] at joint angle(s) q = phi - phi_0 [rad] (scalar or array)."""
        return np.interp(q, self.q, self.tau, left=self.tau[0], right=self.post_snap_torque)

    def backward_displacement(self, q):
        """Probe displacement [m] of the backward push at joint angle q >= 0 (rig geometry)."""
        a = self.a
        return a.barb_length * (math.cos(a.barb_angle) - math.cos(a.barb_angle + q))
