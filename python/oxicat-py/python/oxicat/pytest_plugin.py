"""The pytest plugin of the oxicat package: the ``veth`` and ``segment`` fixtures and the
``segment`` marker, for tests of an EtherCAT master.

Installing the package registers it (entry point ``pytest11``: ``oxicat``), so a test
needs no conftest::

    @pytest.mark.segment(esi=["EL2008.xml"])
    def test_my_master(segment, veth):
        master = pysoem.Master()
        master.open(veth[0])
        assert master.config_init() == len(segment)
        ...

``segment`` serves a virtual segment (``oxicat.Segment``) on one end of a fresh veth pair;
the master under test opens the other end, ``veth[0]``. The devices are those of the
``segment`` marker (its keywords are ``Segment``'s: ``devices``, ``esi``,
``segment_file``, ``slowdown``), ``demo:2`` without one. A fixture of the same name in a
``conftest.py`` overrides the plugin's; ``-p no:oxicat`` switches it off. Needs root for
the veth pair: skipped without it, an error when ``CI`` is set.
"""

import os

import pytest

import oxicat
from oxicat.testing import can_make_veth, veth_pair


def pytest_configure(config):
    config.addinivalue_line(
        "markers",
        "segment(devices=None, esi=None, segment_file=None, slowdown=1): what the oxicat "
        "segment fixture serves",
    )


def _need_root():
    if not can_make_veth():
        why = "needs root and `ip` for a veth pair"
        if os.environ.get("CI"):
            pytest.fail(f"{why} (mandatory under CI)")
        pytest.skip(why)


@pytest.fixture
def veth():
    """A veth pair ``(master_end, segment_end)``, removed after the test."""
    _need_root()
    with veth_pair() as pair:
        yield pair


@pytest.fixture
def segment(request, veth):
    """``oxicat.Segment`` served on ``veth[1]`` for the test, stopped afterwards."""
    marker = request.node.get_closest_marker("segment")
    kw = dict(marker.kwargs) if marker else {}
    devices = kw.pop("devices", None)
    if devices is None and not kw.get("esi"):
        devices = ["demo:2"]
    with oxicat.Segment(devices, iface=veth[1], **kw) as seg:
        yield seg
