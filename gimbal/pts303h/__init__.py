r"""A PTS-303H pan/tilt head as the tracker meets it: Pelco bytes in, motion (and maybe replies) out.

The paper (Appendix D, Fig. 16) drives a PTS-303H over a UART; its API sets each motor's rotation
*speed* and reports no orientation, so the authors calibrated a command -> speed lookup table and
integrated it ("Gimbal angle calibration").  This model is what makes that calibration necessary:

* **Unit-specific speed curve.**  Each speed byte ``b`` maps to a true speed through a monotone,
  nonlinear curve with a dead zone ``b <= b0`` (zero speed) and a separate turbo speed (pan byte
  0xFF).  A unit seed draws the unit's gain, exponent, dead-zone byte and per-byte steps, so two
  units differ.  Nominal curve, for ``b0 < b <= 63``:

  .. math:: v(b) = g\,v_{max} \left(\frac{b - b_0}{63 - b_0}\right)^{\gamma}

  with per-byte increments jittered (log-normal) and renormalised, so the unit curve stays
  strictly increasing above the dead zone.  Bytes 0x40-0xFE act as 0x3F.
* **Dead time.**  A command takes effect ``dead_time_s`` after its frame's last byte arrives.
* **Acceleration limit.**  The base speed moves toward the commanded speed at constant
  acceleration ``accel`` (piecewise-constant acceleration segments).
* **Ripple.**  The true speed is the base speed times ``1 + r sin(omega t + phi)``; the frequency
  and phase are drawn per unit.  Because the ripple is a fixed function of time, the angle has a
  closed form on each segment (below) and no integration step exists to change the answer.
* **Travel.**  Pan is continuous (wraps to (-180, 180]); tilt stops at ``tilt_min_deg`` /
  ``tilt_max_deg`` and holds there (speed 0) while commanded into the stop.  The stop absorbs the
  speed: from a hit the base speed ramps again from rest, so a command reversing tilt whose
  deceleration still carries the head into the stop moves it away from the stop at once.
* **Feedback.**  ``'none'`` (the paper: queries go unanswered), ``'at-rest'`` (the family's bench
  notes: correct only when stopped, checksum-valid garbage while moving), ``'always'``.  Replies go
  out in the envelope (D or P) the query came in.
* **Quirks** (switchable in :class:`HeadParams`): absolute sets (0x4B/0x4D) ignored unless the
  line was quiet for ``abs_set_quiet_s``; the tilt word convention (``tilt_zero='zenith'``).

Exact integration
-----------------
On a segment starting at ``t0`` with position ``p0``, base speed ``v0`` and acceleration ``a``
(``D = tau - t0``, ``theta(u) = omega u + phi``):

.. math::

   p(\tau) = p_0 + v_0 D + \tfrac12 a D^2
           + r\Big[-\frac{v_0}{\omega}(\cos\theta_\tau - \cos\theta_0)
                   - \frac{a D}{\omega}\cos\theta_\tau
                   + \frac{a}{\omega^2}(\sin\theta_\tau - \sin\theta_0)\Big]

Segment boundaries are set only by commands, by reaching the commanded speed, by the base speed
crossing zero and by stop hits (found by bracketed root finding on the closed form), never by
how often the model is advanced or queried.

Conventions: pan_deg positive = CCW seen from above = LEFT; tilt_deg positive = UP; Pelco "left"
and "up" increase them.  Time is virtual and always an argument.
"""

from gimbal.pts303h.device import PTS303H
from gimbal.pts303h.kinematics import _pos, _pos1
from gimbal.pts303h.params import AXES, FEEDBACK_MODES, HEAD_FAMILIES, HeadParams, HeadState, unit_speed_table

__all__ = ["AXES", "FEEDBACK_MODES", "HEAD_FAMILIES", "PTS303H", "HeadParams", "HeadState", "unit_speed_table",
           "_pos", "_pos1"]
