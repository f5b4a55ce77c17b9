"""The one parser of indices and layer stacks written as text (`interop.index_text`), used by
``thinfilm-jax fit``, ``fit-map``, ``fit-ellips`` and ``render`` alike: what each form gives,
and a `ValueError` that names what is wrong for everything else."""

import numpy as np
import pytest

from thinfilm_jax.interop.index_text import parse_index, parse_layers
from thinfilm_jax.optics.materials import MATERIALS, refractive_index


@pytest.mark.parametrize("text, want", [
    ("1.46", 1.46), (2, 2.0), (1.5, 1.5), (" 1.33 ", 1.33),
    ("3.9+0.02j", 3.9 + 0.02j), ("2.0+0.5i", 2.0 + 0.5j), ("2.0 + 0.5j", 2.0 + 0.5j),
    ("2.0+0j", 2.0),  # κ = 0: a real index
])
def test_numbers(text, want):
    got = parse_index(text)
    assert got == want and type(got) is type(want)


def test_names_and_files_are_the_materials_index(tmp_path):
    """A bundled name is `refractive_index`'s model (same n + iκ); a CSV file is read too."""
    lam = np.array([450.0, 550.0, 650.0])
    for name in ("SiO2", "Si", "water"):
        np.testing.assert_array_equal(np.asarray(parse_index(name)(lam)),
                                      np.asarray(refractive_index(name)(lam)))
    path = tmp_path / "film.csv"
    path.write_text("wavelength_nm,n,k\n400,1.50,0\n700,1.45,0\n")
    assert abs(complex(np.asarray(parse_index(str(path))(550.0))) - 1.475) < 1e-6


@pytest.mark.parametrize("bad, words", [
    (True, "must be a number"), (None, "must be a number"),
    ("inf", "finite"), (float("nan"), "finite"), ("1+infj", "finite"),
    ("Unobtainium", "unknown material 'Unobtainium'"),
    ("nosuch.yml", "unknown material"),
])
def test_bad_index_names_the_problem(bad, words):
    with pytest.raises(ValueError, match=words):
        parse_index(bad)


def test_unknown_material_lists_the_bundled_ones():
    with pytest.raises(ValueError) as e:
        parse_index("Sio2x")
    assert all(name in str(e.value) for name in MATERIALS)


def test_layers_as_written_and_as_indices():
    assert parse_layers("SiO2:250, Si3N4:80") == [("SiO2", 250.0), ("Si3N4", 80.0)]
    assert parse_layers(["SiO2:250", "1.5:0"]) == [("SiO2", 250.0), ("1.5", 0.0)]
    parsed = parse_layers("SiO2:250,2.0+0.1j:80", indices=True)
    assert parsed[0][0].name == "SiO2" and parsed[1] == (2.0 + 0.1j, 80.0)


@pytest.mark.parametrize("bad, words", [
    ("SiO2 250", r"layer 0 'SiO2 250' is not MATERIAL:THICKNESS_NM"),
    (":250", "is not MATERIAL:THICKNESS_NM"),
    ("SiO2:250,Si3N4:x", r"layer 1 'Si3N4:x': thickness 'x' is not a number"),
    ("SiO2:-1", "finite and >= 0"), ("SiO2:inf", "finite and >= 0"),
    ("SiO2:250,Nope:10", r"layer 1 'Nope:10': unknown material 'Nope'"),
    ([], "layers must be"), (3, "layers must be"),
])
def test_bad_layers_name_the_layer(bad, words):
    with pytest.raises(ValueError, match=words):
        parse_layers(bad)
