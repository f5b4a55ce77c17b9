"""Index models and bundled materials (SPEC §12): the dispersion formulas against published
values and refractiveindex.info's own evaluations, linear interpolation of tables, the YAML and
CSV readers, the errors, gradients against central differences, dtypes and broadcasting, and
every bundled material's κ ≥ 0 and 360–830 nm coverage."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from thinfilm_jax.core._validate import checked
from thinfilm_jax.optics.index import (
    CompositeIndex,
    ConstantIndex,
    FormulaIndex,
    IndexModel,
    TabulatedIndex,
    cauchy,
    check_wavelengths,
    index_at,
    is_index_model,
    sellmeier,
)
from thinfilm_jax.optics.materials import MATERIALS, refractive_index

# refractiveindex.info's evaluations of the formulas (λ µm, n), as tabulated by that database
# (copies in jaxlayerlumos 0.3.5, materials/*.csv, 13 significant digits): an independent
# implementation of formula 1 and formula 6.
RII_SILICA = [(0.2251, 1.5240789072975), (0.5349, 1.4605730794883), (1.271, 1.4472455774929)]
RII_SAPPHIRE_O = [(0.2133, 1.8882235599463), (0.477, 1.7763969806669),
                  (1.066, 1.7544492215126)]
RII_SI3N4 = [(0.207, 2.5124698613091), (0.4859, 2.0382700672906), (1.002, 1.9877732210509)]
RII_AIR_PECK = [(0.2153, 1.0003145521507), (0.5941, 1.0002770578576),
                (1.352, 1.0002734494452)]
# Peck & Reeder, J. Opt. Soc. Am. 62, 958 (1972): standard air; formula 6, λ in µm.
PECK_AIR = [8.06051e-5, 2.480990e-2, 132.274, 1.74557e-4, 39.32957]


def n_at(model, lam_nm):
    return float(np.real(model(lam_nm)))


# ----------------------------------------------------------------- published values


@pytest.mark.parametrize("name, table", [("SiO2", RII_SILICA), ("Al2O3", RII_SAPPHIRE_O),
                                         ("Si3N4", RII_SI3N4)])
def test_formula_1_materials_match_refractiveindex_info(name, table):
    m = refractive_index(name)
    for lam_um, n in table:
        assert abs(n_at(m, lam_um * 1000.0) - n) < 1e-12  # measured ≤ 2.3e-16


def test_formulas_against_published_sodium_d_values():
    # Fused silica n_d (He d-line, 587.56 nm) = 1.4585 (Malitson 1965; the formula 1.458464,
    # and 1.458403 at the Na D line, 589.3 nm).
    assert abs(n_at(refractive_index("SiO2"), 587.56) - 1.4585) < 5e-5
    # Dodge 1984: MgF2 ordinary n_D (589.3 nm) = 1.3777 (formula 1.377712).
    assert abs(n_at(refractive_index("MgF2"), 589.3) - 1.3777) < 5e-5
    # Sapphire, ordinary ray: n_D = 1.768 (Malitson & Dodge 1972; formula 1.768076).
    assert abs(n_at(refractive_index("Al2O3"), 589.3) - 1.768) < 5e-4
    # Water at 20 °C: refractiveindex.info prints n = 1.3334 at 587.6 nm for Daimon &
    # Masumura 2007 (absolute, relative to vacuum; formula 1.333403), and the handbook
    # n_D = 1.3330 (relative to air) times n_air = 1.000277 is 1.333369 (formula 1.333349).
    water = refractive_index("water")
    assert abs(n_at(water, 587.6) - 1.3334) < 5e-5
    assert abs(n_at(water, 589.3) - 1.3330 * 1.000277) < 5e-5


def test_formula_6_gases_matches_refractiveindex_info():
    air = FormulaIndex(6, PECK_AIR, (200.0, 1690.0))
    for lam_um, n in RII_AIR_PECK:
        assert abs(n_at(air, lam_um * 1000.0) - n) < 1e-13  # measured ≤ 3.3e-14


def test_formulas_3_to_9_as_defined():
    lam = np.array([400.0, 633.0, 1000.0, 1550.0])
    x = lam / 1000.0
    c = [2.1, 0.03, 0.4, 0.05, 2.0, 0.9, 0.07, 0.01, 1.0]

    def n(f, coef):
        return np.asarray(FormulaIndex(f, coef)(lam)).real

    # 3 polynomial: n² = C1 + C2 λ^C3 + C4 λ^C5
    np.testing.assert_allclose(n(3, [2.1, -0.01, 2.0, 0.02, -2.0]) ** 2,
                               2.1 - 0.01 * x**2 + 0.02 / x**2, rtol=1e-14)
    # 4 reduces to formula 2 (C3 = C7 = 2, C5 = C9 = 1), plus the polynomial tail
    f2 = n(2, [0.2, 0.6, 0.01, 0.4, 100.0])
    np.testing.assert_allclose(n(4, [1.2, 0.6, 2.0, 0.01, 1.0, 0.4, 2.0, 100.0, 1.0]), f2,
                               rtol=1e-14)
    np.testing.assert_allclose(
        n(4, [1.2, 0.6, 2.0, 0.1, 2.0, 0.4, 2.0, 10.0, 2.0, -0.003, 2.0]) ** 2,
        f2**2 - 0.003 * x**2, rtol=1e-14)
    # 5 Cauchy: n = C1 + C2 λ^C3 + C4 λ^C5
    np.testing.assert_allclose(n(5, [1.5, 0.004, -2.0, 1e-4, -4.0]),
                               1.5 + 0.004 / x**2 + 1e-4 / x**4, rtol=1e-15)
    # 7 Herzberger
    L = 1.0 / (x**2 - 0.028)
    np.testing.assert_allclose(n(7, c[:6]), c[0] + c[1] * L + c[2] * L**2 + c[3] * x**2
                               + c[4] * x**4 + c[5] * x**6, rtol=1e-14)
    # 8 Retro: (n² − 1)/(n² + 2) = C1 + C2 λ²/(λ² − C3) + C4 λ²
    r = n(8, [0.2, 0.05, 0.02, -0.001])
    np.testing.assert_allclose((r**2 - 1) / (r**2 + 2),
                               0.2 + 0.05 * x**2 / (x**2 - 0.02) - 0.001 * x**2, rtol=1e-14)
    # 9 Exotic: n² = C1 + C2/(λ² − C3) + C4 (λ − C5)/((λ − C5)² + C6)
    e = n(9, [2.0, 0.05, 0.03, 0.1, 0.5, 0.2])
    np.testing.assert_allclose(e**2, 2.0 + 0.05 / (x**2 - 0.03)
                               + 0.1 * (x - 0.5) / ((x - 0.5) ** 2 + 0.2), rtol=1e-14)
    # Missing trailing coefficients are zero; a zero-padded formula-4 term stays 0 at
    # λ² = C4^C5 = 0^0 = 1 µm² (no 0/0).
    assert n_at(FormulaIndex(4, [2.25]), 1000.0) == 1.5
    assert n_at(FormulaIndex(7, [1.5]), 1000.0) == 1.5


def test_cauchy_and_sellmeier_helpers():
    assert abs(n_at(cauchy(1.5, 0.004, 1e-4), 500.0) - (1.5 + 0.016 + 0.0016)) < 1e-15
    # Malitson's fused silica in the (B, C µm²) convention is the bundled SiO2.
    s = sellmeier([0.6961663, 0.4079426, 0.8974794],
                  np.square([0.0684043, 0.1162414, 9.896161]))
    lam = np.linspace(300.0, 900.0, 7)
    np.testing.assert_allclose(s(lam), refractive_index("SiO2")(lam), rtol=1e-15)


# ----------------------------------------------------------------- tables


def test_tabulated_exact_at_nodes_and_linear_between():
    wl = np.array([400.0, 500.0, 650.0, 800.0])
    n = np.array([1.6, 1.5, 1.45, 1.44])
    k = np.array([0.3, 0.0, 0.1, 0.2])
    m = TabulatedIndex(wl, n, k)
    np.testing.assert_array_equal(np.asarray(m(wl)), n + 1j * k)
    t = 0.3
    mid = m(500.0 + t * 150.0)
    assert abs(complex(mid) - complex((1 - t) * 1.5 + t * 1.45, t * 0.1)) < 1e-15
    assert m.wavelength_range == (400.0, 800.0)


def test_bundled_tables_exact_at_their_rows():
    m = refractive_index("Au")
    w = np.asarray(m.wavelength_nm)
    rows = np.loadtxt(MATERIALS_DIR() / "Au-Rakic-1998.csv", delimiter=",", comments="#",
                      skiprows=3)
    np.testing.assert_array_equal(w, rows[:, 0])
    np.testing.assert_array_equal(np.asarray(m(w)), rows[:, 1] + 1j * rows[:, 2])


# Linear interpolation from every other row, error at the dropped rows over 360-830 nm
# (relative |Δ(n + iκ)| / |n + iκ|): measured Si 6.69e-2 (0.15e-2 over 500-830 nm), TiO2
# 2.10e-4, Al 1.05e-3, Ag 4.76e-3, Au 3.03e-3, Cu 3.78e-3, Cr 4.67e-5 (docs/how-to/materials.md).
HALF_TABLE_REL_ERROR = {"Si": 6.8e-2, "TiO2": 2.2e-4, "Al": 1.1e-3, "Ag": 4.8e-3,
                        "Au": 3.1e-3, "Cu": 3.8e-3, "Cr": 4.8e-5}


@pytest.mark.parametrize("name", sorted(HALF_TABLE_REL_ERROR))
def test_linear_interpolation_error_of_the_bundled_tables(name):
    m = refractive_index(name)
    w, n, k = (np.asarray(a) for a in (m.wavelength_nm, m.n, m.k))
    half = TabulatedIndex(w[::2], n[::2], k[::2])
    sel = np.arange(1, len(w) - 1, 2)
    sel = sel[(w[sel] >= 360.0) & (w[sel] <= 830.0)]
    ref = n[sel] + 1j * k[sel]
    rel = np.abs(np.asarray(half(w[sel])) - ref) / np.abs(ref)
    assert rel.max() < HALF_TABLE_REL_ERROR[name]
    assert rel.max() > HALF_TABLE_REL_ERROR[name] / 2  # the documented number is current


def MATERIALS_DIR():
    import importlib.resources

    return importlib.resources.files("thinfilm_jax") / "data" / "materials"


# ----------------------------------------------------------------- bundled materials


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_bundled_material_covers_the_observers_and_absorbs(name):
    m = refractive_index(name)
    mat = MATERIALS[name]
    assert m.wavelength_range == mat.wavelength_range
    assert m.wavelength_range[0] <= 360.0 and m.wavelength_range[1] >= 830.0
    assert re.search(r"\(\d{4}\)", mat.citation)  # authors, journal, (year)
    v = np.asarray(m(np.arange(360.0, 831.0)))
    assert np.all(np.isfinite(v)) and np.all(v.imag >= 0) and np.all(v.real > 0)
    assert refractive_index(name.upper()) is m  # case-insensitive, cached


def test_metals_are_metals_and_dielectrics_are_transparent():
    for name in ("Al", "Ag", "Au", "Cu", "Cr"):
        assert refractive_index(name)(550.0).imag > 2.0
    for name in ("SiO2", "Si3N4", "Al2O3", "MgF2", "water"):
        assert refractive_index(name)(550.0).imag == 0.0


# ----------------------------------------------------------------- files

SILICA_YAML = """\
REFERENCES: "I. H. Malitson. <a href=\\"https://doi.org/10.1364/JOSA.55.001205\\"><i>J.
  Opt. Soc. Am.</i> <b>55</b>, 1205-1208 (1965)</a>"
COMMENTS: "Room temperature"
DATA:
  - type: formula 1
    wavelength_range: 0.21 6.7
    coefficients: 0 0.6961663 0.0684043 0.4079426 0.1162414 0.8974794 9.896161
SPECS:
  n_absolute: false
"""

NK_YAML = """\
REFERENCES: "Test table"
DATA:
  - type: tabulated nk
    data: |
        0.30 1.20 2.50
        0.50 0.80 3.00
        0.90 0.50 6.00
"""

FORMULA_K_YAML = """\
DATA:
  - type: formula 2
    range: 0.2 1.0
    coefficients: 0 1.0 0.01
  - type: tabulated k
    data: |
        0.25 0.0
        0.45 0.02
        1.20 0.01
"""


def test_yaml_formula_round_trip(tmp_path):
    p = tmp_path / "silica.yml"
    p.write_text(SILICA_YAML)
    m = refractive_index(p)
    assert isinstance(m, FormulaIndex) and m.wavelength_range == (210.0, 6700.0)
    assert "Malitson" in m.citation and "<" not in m.citation
    lam = np.linspace(210.0, 2000.0, 9)
    np.testing.assert_array_equal(m(lam), refractive_index("SiO2")(lam))
    assert refractive_index(str(p)).wavelength_range == (210.0, 6700.0)


def test_yaml_tabulated_nk_and_formula_plus_k(tmp_path):
    p = tmp_path / "metal.yaml"
    p.write_text(NK_YAML)
    m = refractive_index(p)
    assert isinstance(m, TabulatedIndex) and m.wavelength_range == (300.0, 900.0)
    np.testing.assert_allclose(m(np.array([300.0, 400.0, 900.0])),
                               [1.2 + 2.5j, 1.0 + 2.75j, 0.5 + 6j], rtol=1e-15)
    q = tmp_path / "film.yml"
    q.write_text(FORMULA_K_YAML)
    c = refractive_index(q)
    assert isinstance(c, CompositeIndex) and c.wavelength_range == (250.0, 1000.0)
    v = complex(c(350.0))
    assert abs(v.real - np.sqrt(1 + 0.35**2 / (0.35**2 - 0.01))) < 1e-15
    assert abs(v.imag - 0.01) < 1e-15
    with pytest.raises(ValueError, match=r"1100 nm lies outside \[250, 1000\] nm"):
        c(1100.0)


def test_csv_round_trip(tmp_path):
    p = tmp_path / "film.csv"
    p.write_text("# a comment\nwavelength_um, n, k\n0.4,1.5,0.01\n0.6,1.45,0\n0.8,1.44,0\n")
    m = refractive_index(p)
    assert m.wavelength_range == (400.0, 800.0)
    assert abs(complex(m(500.0)) - (1.475 + 0.005j)) < 1e-15
    q = tmp_path / "nk.csv"
    q.write_text("n,wavelength_nm\n1.3,350\n1.2,900\n")  # any order, k optional
    assert complex(refractive_index(q)(900.0)) == 1.2 + 0j


@pytest.mark.parametrize("text, match", [
    ("DATA: [unclosed", "not valid YAML"),
    ("REFERENCES: x\n", "DATA"),
    ("DATA:\n  - type: tabulated xyz\n    data: '1 2'\n", "unsupported DATA type"),
    ("DATA:\n  - type: tabulated nk\n    data: |\n      0.4 1.5\n      0.5 1.4\n", "row 1"),
    ("DATA:\n  - type: tabulated nk\n    data: |\n      0.4 1.5 0\n      0.5 1.4 -0.1\n",
     "k must be ≥ 0"),
    ("DATA:\n  - type: tabulated n\n    data: |\n      0.5 1.5\n      0.4 1.4\n",
     "increase strictly"),
    ("DATA:\n  - type: formula 1\n    wavelength_range: 0.3 0.2\n    coefficients: 0 1 0.1\n",
     "wavelength_range"),
    ("DATA:\n  - type: formula 1\n    wavelength_range: 0.2 0.9\n    coefficients: 0 1\n",
     "pairs"),
    ("DATA:\n  - type: tabulated k\n    data: |\n      0.4 0.1\n      0.5 0.1\n", "source of n"),
])
def test_malformed_yaml_names_problem_and_file(tmp_path, text, match):
    p = tmp_path / "bad.yml"
    p.write_text(text)
    with pytest.raises(ValueError, match=match) as e:
        refractive_index(p)
    assert "bad.yml" in str(e.value)


@pytest.mark.parametrize("text, match", [
    ("", "no header"),
    ("wavelength_nm,k\n400,0\n500,0\n", "n"),
    ("wavelength_nm,n,colour\n400,1,2\n500,1,2\n", "columns"),
    ("wavelength_nm,n\n400,1.5\n500\n", "line 3"),
    ("wavelength_nm,n\n400,abc\n500,1.4\n", "not a number"),
    ("wavelength_nm,n,k\n400,1.5,0.1\n500,1.4,-0.01\n", "k must be ≥ 0"),
    ("wavelength_nm,n\n400,1.5\n400,1.4\n", "increase strictly"),
    ("wavelength_nm,n\n400,1.5\n", "at least two"),
])
def test_malformed_csv_names_problem_and_file(tmp_path, text, match):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(ValueError, match=match) as e:
        refractive_index(p)
    assert "bad.csv" in str(e.value)


def test_unknown_name_lists_the_bundled_materials():
    with pytest.raises(ValueError) as e:
        refractive_index("unobtainium")
    for name in MATERIALS:
        assert name in str(e.value)
    with pytest.raises(TypeError):
        refractive_index(None)


def test_out_of_range_names_the_range_never_extrapolates():
    au = refractive_index("Au")
    with pytest.raises(ValueError, match=r"240 nm lies outside \[247\.97, 1998\] nm.*Rakić"):
        au(np.array([300.0, 240.0]))
    with pytest.raises(ValueError, match=r"\[210, 6700\]"):
        refractive_index("SiO2")(200.0)
    with pytest.raises(ValueError, match="must be finite"):
        au(np.nan)
    check_wavelengths(au, [247.97, 1998.0])  # the ends are inside
    with pytest.raises(ValueError, match="lambda_film"):
        check_wavelengths(au, 2000.0, name="lambda_film")
    # Traced: unchecked by default (jnp.interp holds the end value) ...
    assert complex(jax.jit(lambda m, w: m(w))(au, 200.0)) == complex(au(247.97))
    # ... checked inside `checked`, as an error when the result is computed.
    with pytest.raises(Exception, match=r"247\.97"):
        jax.block_until_ready(jax.jit(checked(lambda w: au(w)))(200.0))


def test_composite_of_disjoint_ranges_is_an_error():
    with pytest.raises(ValueError, match="do not overlap"):
        CompositeIndex(refractive_index("Si"), TabulatedIndex([1500.0, 1600.0], [0, 0], [0, 1]))


def test_negative_kappa_is_an_error():
    with pytest.raises(ValueError, match="≥ 0"):
        refractive_index(1.5 - 0.1j)
    with pytest.raises(ValueError, match="≥ 0"):
        TabulatedIndex([400.0, 500.0], [1.5, 1.5], [0.1, -0.1])


# ----------------------------------------------------------------- the pytree contract


def test_constants_models_and_index_at():
    c = refractive_index(1.5 + 0.25j)
    assert isinstance(c, ConstantIndex) and is_index_model(c)
    assert c.wavelength_range == (0.0, np.inf)
    assert complex(c(700.0)) == 1.5 + 0.25j
    assert refractive_index(c) is c
    assert complex(refractive_index(2)(500.0)) == 2 + 0j
    assert index_at(c, 500.0) == c(500.0)
    assert index_at(1.5, 500.0) == 1.5 and not is_index_model(1.5)


MODELS = {
    "constant": ConstantIndex(1.5 + 0.1j),
    "table": refractive_index("Ag"),
    "formula": refractive_index("MgF2"),
    "composite": CompositeIndex(refractive_index("SiO2"),
                                TabulatedIndex([300.0, 900.0], [0.0, 0.0], [0.0, 0.01])),
}


@pytest.mark.parametrize("kind", sorted(MODELS))
def test_dtype_and_broadcasting(kind):
    m = MODELS[kind]
    for dt, ct in ((jnp.float32, jnp.complex64), (jnp.float64, jnp.complex128)):
        for shape in ((), (3,), (2, 3, 1)):
            w = jnp.full(shape, 550.0, dt) + jnp.arange(np.prod(shape, dtype=int), dtype=dt
                                                        ).reshape(shape)
            v = m(w)
            assert v.dtype == ct and v.shape == shape
    assert m(np.array([500, 600])).dtype == jnp.complex128  # integers: the default float
    w = jnp.linspace(400.0, 800.0, 5)
    np.testing.assert_array_equal(jax.jit(lambda mm, x: mm(x))(m, w), m(w))
    np.testing.assert_array_equal(jax.vmap(m)(w), m(w))
    v32 = np.asarray(m(w.astype(jnp.float32)))
    np.testing.assert_allclose(v32, m(w), rtol=2e-6, atol=1e-7)  # measured ≤ 1.0e-7 rel.


def test_constant_array_broadcasts_with_wavelengths():
    c = ConstantIndex(jnp.array([[1.3], [1.5]]))
    assert c(jnp.linspace(400.0, 700.0, 4)).shape == (2, 4)


def test_models_are_pytrees_with_static_metadata():
    m = refractive_index("water")
    leaves = jax.tree_util.tree_leaves(m)
    assert len(leaves) == 1 and leaves[0].shape == (9,)
    m2 = jax.tree_util.tree_map(lambda x: x * 1.0, m)
    assert m2.name == "water" and m2.wavelength_range == (182.0, 1129.0)
    assert isinstance(m, IndexModel)


# ----------------------------------------------------------------- gradients


def central(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


def test_gradient_wrt_cauchy_coefficients_matches_central_differences():
    lam = jnp.array([420.0, 550.0, 700.0])

    def loss(A, B):
        return jnp.sum(jnp.real(cauchy(A, B)(lam)) ** 2)

    gA, gB = jax.grad(loss, argnums=(0, 1))(1.46, 0.0035)
    assert abs(gA - central(lambda a: loss(a, 0.0035), 1.46, 1e-6)) < 1e-8
    assert abs(gB - central(lambda b: loss(1.46, b), 0.0035, 1e-7)) < 1e-7
    assert abs(gB - 2 * sum((1.46 + 0.0035 / x**2) / x**2 for x in (0.42, 0.55, 0.7))) < 1e-10


def test_gradient_wrt_sellmeier_coefficients_and_wavelength():
    m = refractive_index("SiO2")
    lam = jnp.array([400.0, 633.0])
    g = jax.grad(lambda mm: jnp.sum(jnp.real(mm(lam))))(m).coefficients
    c0 = np.asarray(m.coefficients)
    for i in (1, 2, 6):
        e = np.zeros_like(c0)
        e[i] = 1.0
        fd = central(lambda t: float(jnp.sum(jnp.real(FormulaIndex(1, c0 + t * e)(lam)))),
                     0.0, 1e-6)
        assert abs(g[i] - fd) < 1e-8 * max(1.0, abs(fd))  # measured ≤ 3e-10
    # dn/dλ at 587.6 nm against a central difference (h = 1e-3 nm)
    dn = jax.grad(lambda w: jnp.real(m(w)))(587.6)
    assert abs(dn - central(lambda w: n_at(m, w), 587.6, 1e-3)) < 1e-10


def test_gradient_wrt_table_values_is_the_interpolation_weights():
    wl = jnp.array([400.0, 500.0, 600.0])
    n = jnp.array([1.5, 1.4, 1.35])
    k = jnp.array([0.1, 0.2, 0.0])

    def f(n, k):
        v = TabulatedIndex(wl, n, k)(460.0)
        return jnp.real(v) + 3.0 * jnp.imag(v)

    gn, gk = jax.grad(f, argnums=(0, 1))(n, k)
    np.testing.assert_allclose(gn, [0.4, 0.6, 0.0], atol=1e-15)
    np.testing.assert_allclose(gk, [1.2, 1.8, 0.0], atol=1e-15)


def test_bundled_materials_first_built_inside_jit():
    """The bundled materials are cached per process (`materials._bundled`); one first asked
    for inside `jit` is built concretely, so the cache holds no tracer of that trace and a
    later jit(grad) and eager call work (a leaked tracer raised UnexpectedTracerError)."""
    from thinfilm_jax.optics import materials

    materials._bundled.cache_clear()
    try:
        def f(lam):
            return jnp.real(refractive_index("Si")(lam) + refractive_index("SiO2")(lam))

        value = jax.jit(f)(600.0)
        for name in ("Si", "SiO2"):
            assert not any(isinstance(x, jax.core.Tracer)
                           for x in jax.tree.leaves(materials._bundled(name)))
        np.testing.assert_allclose(jax.jit(f)(600.0), f(600.0), rtol=1e-12)
        np.testing.assert_allclose(value, f(600.0), rtol=1e-12)
        g = jax.jit(jax.grad(f))(600.0)
        assert np.isfinite(float(g)) and float(g) != 0.0
    finally:
        materials._bundled.cache_clear()
