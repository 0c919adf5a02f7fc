"""Virtual EtherCAT segments (oxicat) for Python tests.

``Segment`` serves the devices of ``oxicat sim`` (or twins of vendors' devices from their
ESI) on a UDP port or a network interface from a background thread, while a master under
test (pysoem, an application) drives them; it reads the slaves' process data and injects
faults. ``oxicat.testing`` has a veth pair for masters that speak raw Ethernet only.
"""

from ._oxicat import OxicatError, Segment, device_list

__all__ = ["OxicatError", "Segment", "device_list"]
