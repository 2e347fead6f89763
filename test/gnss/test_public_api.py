"""The package's public API: every name in ``ins_gnss_ros.gnss.__all__`` is its module's."""
import importlib

import pytest

import ins_gnss_ros.gnss as gnss


@pytest.mark.parametrize("name", gnss.__all__)
def test_public_name_is_the_defining_modules(name):
    module = importlib.import_module(f"ins_gnss_ros.gnss.{gnss._MODULE_OF[name]}")
    assert getattr(gnss, name) is getattr(module, name)


def test_unknown_names_and_subpackages():
    with pytest.raises(AttributeError):
        gnss.no_such_name  # noqa: B018
    from ins_gnss_ros.gnss import ephemeris_data

    assert ephemeris_data.load
