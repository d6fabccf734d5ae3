"""One random stream per effect: listing or removing one effect never changes another's draws
(``sim.effects.effect_rng``: one stream per effect name; the link's ``sim.virtual_uart``).

fig12 with every effect a scene can list (rates raised so that each acts within 5 s), then again
with each effect removed in turn.  Every other effect's draws are compared with the full run's:

* the link's bit errors and drops, per byte sent (a command every frame: the same bytes count in
  every run), read off what the line delivers (which bytes arrive, which bits differ);
* the per-hit sensor effects (return probability, dropouts, range and angular noise), as the arrays
  their draw functions return, concatenated: the hits per frame follow the head and the scan, so
  the runs may draw different counts, and the sequences must agree on their common length;
* sunlight, stray returns and motor speed noise, whose draws depend on the scan alone: the stream's
  end state;
* the head's dead-time jitter (one uniform per frame the head receives: the link's drops and bit
  errors change how many) and the host's link latency (one per command sent): the stream's end state
  is its own seed's stream after exactly that many draws, so nothing else drew from it; the wind's
  gust phases likewise (drawn once, when the head is built);
* the head's thermal drift and backlash and the lidar's clock drift draw nothing; listing them must change no
  other effect's draws.

Bound: equal to the bit.  On 802524f removing ``uart_drops`` changed the bit errors of most frames
(the two shared one stream).
"""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sim import effects as fx
from sim.scene import scene_from_mapping
from sim.virtual_uart import VirtualUart

ROOT = Path(__file__).resolve().parents[2]
EVERY = ["range_noise", "motor_speed_noise", "return_probability", "angular_noise", "dropouts", "sunlight",
         "beam_footprint", "uart_bit_errors", "uart_drops", "uart_echo", "head_ripple", "stray_returns",
         "head_thermal_drift", "head_dead_time_jitter", "link_latency_jitter", "lidar_clock_drift", "head_backlash",
         "head_wind"]
PARAMS = {"uart_bit_error_rate": 0.01, "uart_drop_rate": 0.02, "dropout_rate": 0.05, "sunlight_rate": 1e-3,
          "stray_rate_hz": 20.0}
PER_HIT = {"return_probability": "return_draws", "dropouts": "dropout_draws", "range_noise": "range_noise_normals",
           "angular_noise": "angular_noise_normals"}


def _scene(effects):
    data = tomllib.loads((ROOT / "scenes" / "fig12-tracking.toml").read_text())
    data["scene"]["effects"] = list(effects)
    data["effects"] = {k: v for k, v in PARAMS.items()
                       if any(k in fx_params for e, fx_params in _defaults().items() if e in effects)}
    return replace(scene_from_mapping(data, "every effect"), duration_s=5.0)


def _defaults():
    from sim.scene import EFFECT_DEFAULTS
    return EFFECT_DEFAULTS


def _run(effects, monkeypatch):
    from sim.loop import ClosedLoop

    drawn = {e: [] for e in PER_HIT}
    for effect, name in PER_HIT.items():
        real = getattr(fx, name)

        def recording(rng, n, _real=real, _effect=effect):
            out = _real(rng, n)
            drawn[_effect].append(np.array(out, copy=True).reshape(-1))
            return out
        monkeypatch.setattr(fx, name, recording)
    link = []   # per send: (bytes sent, indices delivered, bytes delivered)
    real_send = VirtualUart.send

    def send(self, data, t_s):
        out = real_send(self, data, t_s)
        start = max(float(t_s), self.line_free_at_s - self.byte_time_s * len(data))
        idx = [int(round((t - start) / self.byte_time_s)) - 1 for t, _ in out]
        link.append((bytes(data), idx, b"".join(b for _, b in out)))
        return out
    monkeypatch.setattr(VirtualUart, "send", send)
    loop = ClosedLoop(_scene(effects))
    loop.run()
    monkeypatch.undo()
    states = {"sunlight": loop.sensor.rngs["sunlight"].bit_generator.state if "sunlight" in effects else None,
              "stray_returns": (loop.sensor.rngs["stray_returns"].bit_generator.state
                                if "stray_returns" in effects else None),
              "motor_speed_noise": loop.scan.noise_draws,
              "head_dead_time_jitter": (loop.head._dead_time_rng.bit_generator.state, loop.head.frames_received,
                                        loop.scene.param("dead_time_jitter_s"))
              if "head_dead_time_jitter" in effects else None,
              "link_latency_jitter": (loop.link_jitter_rng.bit_generator.state, len(link),
                                      loop.scene.param("link_latency_jitter_s"))
              if "link_latency_jitter" in effects else None,
              "head_wind": (loop.head.deflection.phase, fx.effect_rng(loop.scene.seed, "head_wind").uniform(0, 2 * np.pi, 16))
              if "head_wind" in effects else None}
    return {e: np.concatenate(v) if v else np.zeros(0) for e, v in drawn.items()}, link, states


def _link_draws(link):
    """Per byte sent: delivered or not (drops), and the bits flipped if delivered (bit errors)."""
    kept, flips = [], []
    for data, idx, got in link:
        k = np.zeros(len(data), bool)
        k[idx] = True
        f = np.full(len(data), -1)
        f[idx] = np.frombuffer(data, np.uint8)[idx] ^ np.frombuffer(got, np.uint8)
        kept.append(k)
        flips.append(f)
    return np.concatenate(kept), np.concatenate(flips)


@pytest.fixture(scope="module")
def full_run():
    mp = pytest.MonkeyPatch()
    try:
        return _run(EVERY, mp)
    finally:
        mp.undo()


@pytest.mark.parametrize("removed", EVERY)
def test_removing_one_effect_leaves_every_other_effects_draws(removed, full_run, monkeypatch):
    drawn_all, link_all, states_all = full_run
    drawn, link, states = _run([e for e in EVERY if e != removed], monkeypatch)
    for effect in PER_HIT:
        if effect == removed:
            assert drawn[effect].size == 0
            continue
        a, b = drawn_all[effect], drawn[effect]
        n = min(a.size, b.size)
        assert n > 1000, effect
        assert np.array_equal(a[:n], b[:n]), f"{effect}'s draws changed when {removed} was removed"
    if removed != "sunlight":
        assert states["sunlight"] == states_all["sunlight"]
    if removed != "stray_returns":
        assert states["stray_returns"] == states_all["stray_returns"]
    if removed != "motor_speed_noise":
        assert states["motor_speed_noise"] == states_all["motor_speed_noise"]
    if removed != "head_wind":
        assert np.array_equal(*states["head_wind"]) and np.array_equal(states["head_wind"][0], states_all["head_wind"][0])
    for own in ("head_dead_time_jitter", "link_latency_jitter"):
        if removed != own:
            state, n, param = states[own]
            fresh = fx.effect_rng(_scene(EVERY).seed, own)
            if own == "head_dead_time_jitter":
                fresh.random(n)
            else:
                for _ in range(n):
                    fx.link_latency_draw(fresh, param)
            assert n >= 10 and state == fresh.bit_generator.state, f"{own}'s stream was drawn by another effect"
    kept_all, flips_all = _link_draws(link_all)
    kept, flips = _link_draws(link)
    assert kept.size == kept_all.size == 7 * 50   # one Pelco-D frame per 100 ms frame
    if removed != "uart_drops":
        assert np.array_equal(kept, kept_all), f"the link's drops changed when {removed} was removed"
        assert (~kept_all).sum() >= 2
    if removed != "uart_bit_errors":
        both = kept & kept_all
        assert np.array_equal(flips[both], flips_all[both]), f"the bit errors changed when {removed} was removed"
        assert np.count_nonzero(flips_all[both] > 0) >= 5
