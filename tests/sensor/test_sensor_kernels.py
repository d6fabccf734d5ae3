"""The one-pass returns kernel agrees with its numpy twin (same draws, same points)."""

import itertools

import numpy as np
import pytest

from foveatrack.livox.protocol import quantise_to_mm_grid
from sensor_twins import returns_twin
from sim import effects as fx
from sim import sensor_kernels as sk
from sim.scan.kernels import RAY_GRAZING, RAY_OK, RAY_TIR

EFFECTS = ("return_probability", "dropouts", "range_noise", "angular_noise")
PARAMS = {"range_80pct_m": 60.0, "dropout_rate": 0.2, "range_noise_m": 0.05, "angular_noise_deg": 0.3}


def _rays(seed, n):
    rng = np.random.default_rng(seed)
    prim = rng.integers(-1, 6, n)                       # -1: nothing hit
    status = rng.choice([RAY_OK, RAY_OK, RAY_OK, RAY_TIR, RAY_GRAZING], n).astype(np.uint8)
    range_m = rng.uniform(1.0, 90.0, n)                 # around the 60 m range limit and past it
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_ns = np.sort(rng.integers(0, 10**8, n))
    refl = np.array([0.05, 0.3, 0.8, 1.2, 0.0, 0.5])   # out-of-range values are clipped
    return prim, status, range_m, d, t_ns, refl


@pytest.mark.parametrize("listed", [c for k in range(len(EFFECTS) + 1) for c in itertools.combinations(EFFECTS, k)])
@pytest.mark.parametrize("n", [0, 1, 4000])
@pytest.mark.parametrize("envelope", [(0.0, np.inf), (5.0, 70.0)])
def test_kernel_matches_twin(listed, n, envelope):
    prim, status, range_m, d, t_ns, refl = _rays(n + len(listed), n)
    seeds = {e: 100 + i for i, e in enumerate(EFFECTS)}
    twin = returns_twin(prim, status, range_m, d, t_ns, refl, 2,
                        {e: np.random.default_rng(seeds[e]) for e in listed}, PARAMS, envelope)
    n_hit = sk.count_hits_kernel(prim, status)
    g = {e: np.random.default_rng(seeds[e]) for e in listed}
    draws = {
        "return_probability": fx.return_draws(g["return_probability"], n_hit) if "return_probability" in g else np.zeros(0),
        "dropouts": fx.dropout_draws(g["dropouts"], n_hit) if "dropouts" in g else np.zeros(0),
        "range_noise": fx.range_noise_normals(g["range_noise"], n_hit) if "range_noise" in g else np.zeros(0),
        "angular_noise": (fx.angular_noise_normals(g["angular_noise"], n_hit)
                          if "angular_noise" in g and n_hit else np.zeros(0)),
    }
    out = (np.empty((n_hit, 3)), np.empty(n_hit, np.int64), np.empty(n_hit, np.uint8), np.empty(n_hit, np.bool_))
    refl_byte = np.clip(np.round(refl * 100), 0, 255).astype(np.uint8)
    args = (prim, status, range_m, d, t_ns, fx.range_limit_m(refl, PARAMS["range_80pct_m"]),
            refl_byte, 2, draws["return_probability"], draws["dropouts"], PARAMS["dropout_rate"] if "dropouts" in g else 0.0,
            draws["range_noise"], PARAMS["range_noise_m"], draws["angular_noise"], np.radians(PARAMS["angular_noise_deg"]))
    off = (refl, np.zeros(0), 0.0, 0.0, np.zeros(0), 1)     # incidence, weather, noise model: off
    k = sk.assemble_returns_kernel(*args, False, *envelope, *off, *out)
    got = tuple(a[:k] for a in out)
    # on the mm grid in the same pass: the bits of quantise_to_mm_grid applied afterwards
    out_mm = (np.empty((n_hit, 3)), np.empty(n_hit, np.int64), np.empty(n_hit, np.uint8), np.empty(n_hit, np.bool_))
    assert sk.assemble_returns_kernel(*args, True, *envelope, *off, *out_mm) == k
    assert np.array_equal(out_mm[0][:k].view(np.int64), quantise_to_mm_grid(got[0]).view(np.int64))
    for a, b in zip(out_mm[1:], got[1:]):
        np.testing.assert_array_equal(a[:k], b)
    assert k == len(twin[1])
    np.testing.assert_allclose(got[0], twin[0], rtol=0, atol=1e-12)
    if "angular_noise" not in listed:   # the twin's expressions are the kernel's: the same bits
        assert np.array_equal(got[0].view(np.int64), twin[0].view(np.int64))
    for a, b in zip(got[1:], twin[1:]):
        np.testing.assert_array_equal(a, b)
    # the generators end in the same state: the draws were the same calls
    for e in listed:
        twin_g = np.random.default_rng(seeds[e])
        returns_twin(prim, status, range_m, d, t_ns, refl, 2, {e: twin_g}, PARAMS, envelope)
        assert g[e].bit_generator.state == twin_g.bit_generator.state
    if "return_probability" in listed and n > 100:
        assert 0 < k < n_hit                     # past the range limit some returns are lost
    if n > 100:   # every point inside the envelope (on the measured range); with one, some left out
        r_out = np.linalg.norm(got[0], axis=1)
        assert np.all((r_out >= envelope[0] - 1e-9) & (r_out <= envelope[1] + 1e-9))
        if envelope[1] < np.inf and not listed:
            assert k < n_hit


NEW = ("incidence", "weather", "range_noise_model", "clutter")


@pytest.mark.parametrize("listed", [c for k in range(1, len(NEW) + 1) for c in itertools.combinations(NEW, k)])
@pytest.mark.parametrize("base", [(), ("return_probability", "range_noise"), EFFECTS])
def test_kernel_matches_twin_with_incidence_weather_noise_model(listed, base):
    """The sensor effects of issue 31 (incidence, weather's extinction and droplets, the range noise
    model), each with and without the older ones: kernel and twin give the same points, bit for bit
    but for the angular noise's renormalisation, and the same draws."""
    n = 3000
    prim, status, range_m, d, t_ns, refl = _rays(7 + len(listed) + 3 * len(base), n)
    rng = np.random.default_rng(len(listed))
    cos = rng.uniform(0.0, 1.0, n) if "incidence" in listed else None
    if cos is not None:
        cos[:5] = 0.0        # grazing: no power comes back
    ext = 0.01 if "weather" in listed else 0.0
    limit = 0.15 if "range_noise_model" in listed else 0.0
    clutter = None
    if "clutter" in listed:
        clutter = np.full(n, np.inf)
        pick = rng.choice(n, 200, replace=False)
        clutter[pick] = rng.uniform(0.5, 30.0, 200)
    seeds = {e: 100 + i for i, e in enumerate(EFFECTS)}
    envelope = (1.0, 80.0)
    twin = returns_twin(prim, status, range_m, d, t_ns, refl, 2, {e: np.random.default_rng(seeds[e]) for e in base},
                        PARAMS, envelope, cos, ext, limit, clutter)
    n_hit = sk.count_hits_kernel(prim, status)
    g = {e: np.random.default_rng(seeds[e]) for e in base}
    none = np.zeros(0)
    args = (prim, status, range_m, d, t_ns, fx.range_limit_m(refl, PARAMS["range_80pct_m"]),
            np.clip(np.round(refl * 100), 0, 255).astype(np.uint8), 2,
            fx.return_draws(g["return_probability"], n_hit) if "return_probability" in g else none,
            fx.dropout_draws(g["dropouts"], n_hit) if "dropouts" in g else none,
            PARAMS["dropout_rate"] if "dropouts" in g else 0.0,
            fx.range_noise_normals(g["range_noise"], n_hit) if "range_noise" in g else none, PARAMS["range_noise_m"],
            fx.angular_noise_normals(g["angular_noise"], n_hit) if "angular_noise" in g else none,
            np.radians(PARAMS["angular_noise_deg"]), False, *envelope,
            refl, none if cos is None else cos, ext, limit, none if clutter is None else clutter, 1)
    m = n_hit + (0 if clutter is None else int(np.isfinite(clutter).sum()))
    out = (np.empty((m, 3)), np.empty(m, np.int64), np.empty(m, np.uint8), np.empty(m, np.bool_))
    k = sk.assemble_returns_kernel(*args, *out)
    got = tuple(a[:k] for a in out)
    assert k == len(twin[1])
    np.testing.assert_allclose(got[0], twin[0], rtol=0, atol=1e-12)
    if "angular_noise" not in base:
        assert np.array_equal(got[0].view(np.int64), twin[0].view(np.int64))
    for a, b in zip(got[1:], twin[1:]):
        np.testing.assert_array_equal(a, b)
    if "clutter" in listed:
        # droplets appear at their ranges, weak and never on the target
        r_got = np.linalg.norm(got[0], axis=1)
        c_of = np.full(n, np.inf)
        c_of[status == RAY_OK] = clutter[status == RAY_OK]
        at_c = np.isclose(r_got, c_of[np.searchsorted(t_ns, got[1])], rtol=0, atol=1e-9)
        assert at_c.sum() > 50 and np.all(got[2][at_c] == 1) and not np.any(got[3][at_c])


def test_mm_grid_kernel_is_quantise_to_mm_grid_to_the_bit():
    """The kernels' one-value mm grid against its numpy original: ties to even, both zeros, saturation,
    values a hair either side of a half millimetre, and many random ranges."""
    half = np.arange(-2000, 2001) * 1e-3 + 0.0005
    x = np.concatenate([
        [0.0, -0.0, 0.0005, -0.0005, 0.0015, -0.0015, 0.0025, 1e-4, -1e-4, 3e6, -3e6, 2147483.6475, -2147483.6485,
         1e300, -1e300],
        half, np.nextafter(half, np.inf), np.nextafter(half, -np.inf),
        np.random.default_rng(5).uniform(-500.0, 500.0, 20_001),
    ])
    got = np.empty_like(x)
    sk.quantise_to_mm_grid_kernel(x, got)
    assert np.array_equal(got.view(np.int64), quantise_to_mm_grid(x).view(np.int64))
    xyz = x[:20_001 - 20_001 % 3].reshape(-1, 3)
    got = np.empty_like(xyz)
    sk.quantise_to_mm_grid_kernel(xyz, got)
    assert np.array_equal(got.view(np.int64), quantise_to_mm_grid(xyz).view(np.int64))


@pytest.mark.parametrize("seed", range(4))
def test_object_rays_kernel_matches_twin(seed):
    """Rays per object, with objects of no primitives, the background and a stray row after them,
    rays that hit nothing and rays that left no prism."""
    from sensor_twins import object_rays_twin

    rng = np.random.default_rng(seed)
    sizes = rng.choice([0, 1, 3, 5], rng.integers(1, 8))
    start = np.cumsum(np.concatenate([[0], sizes]))
    n = [0, 1, 5000][seed % 3]
    prim = rng.integers(-1, int(start[-1]) + 3, n)           # past the objects: background, strays
    status = rng.choice([RAY_OK, RAY_OK, RAY_TIR, RAY_GRAZING], n).astype(np.uint8)
    got = np.zeros(sizes.size, dtype=np.int64)
    n_hit = sk.object_rays_kernel(prim, status, np.repeat(np.arange(sizes.size), sizes), got)
    want = object_rays_twin(prim, status, start)
    assert got.dtype == want.dtype and np.array_equal(got, want)
    assert n_hit == sk.count_hits_kernel(prim, status) == int(np.count_nonzero((prim >= 0) & (status == RAY_OK)))
