"""`ModelOptions`: the "auto" Ŝ source of each entry point and the named quality presets."""

import pytest

from thinfilm_jax import ModelOptions
from thinfilm_jax.realtime.options import PRESETS, check_options


def test_presets_are_the_documented_settings():
    """preset("default") is `ModelOptions()` itself (one program with no options at all),
    "fast" changes K only (2 bins), "accurate" the reads per bin only (3): the settings the
    cost and error table of the module docstring measured (figures/improved_bins.md)."""
    assert ModelOptions.preset("default") == ModelOptions()
    assert ModelOptions.preset("fast") == ModelOptions(bins=2)
    assert ModelOptions.preset("accurate") == ModelOptions(bins=3, bin_reads=3)
    assert set(PRESETS) == {"fast", "default", "accurate"}
    for name in PRESETS:
        opts = ModelOptions.preset(name)
        assert opts.checked() == opts._replace(shat="exact")  # valid, Ŝ left to the caller


@pytest.mark.parametrize("bad", ["best", "Fast", "", None, 2])
def test_preset_names_are_checked(bad):
    with pytest.raises(ValueError, match=r"preset.*\['accurate', 'default', 'fast'\]"):
        ModelOptions.preset(bad)


def test_auto_shat_is_the_callers_default():
    """shat="auto" (the default) becomes the entry point's own source; an explicit one is
    kept; anything else is a ValueError naming the field."""
    assert ModelOptions().shat == "auto"
    assert check_options(ModelOptions()).shat == "exact"
    assert check_options(ModelOptions(bins=2), shat_auto="lut") == ModelOptions(shat="lut",
                                                                               bins=2)
    for shat in ("exact", "lut", "gaussian"):
        assert check_options(ModelOptions(shat=shat), shat_auto="lut").shat == shat
    with pytest.raises(ValueError, match="shat"):
        check_options(ModelOptions(shat="fast"))
