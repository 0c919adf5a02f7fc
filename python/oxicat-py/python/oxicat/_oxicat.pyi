"""Type stubs of the native part of the oxicat package (``src/lib.rs``)."""

from os import PathLike
from types import TracebackType
from typing import List, Optional, Tuple, Type, Union

class OxicatError(Exception):
    """A segment could not be built or served, or a slave position does not exist."""

class Segment:
    """A virtual EtherCAT segment served on a UDP port or a network interface from a
    background thread until ``stop()`` (or the end of a ``with`` block)."""

    def __init__(
        self,
        devices: Optional[List[str]] = None,
        *,
        esi: Optional[List[str]] = None,
        segment_file: Optional[Union[str, PathLike[str]]] = None,
        udp: Optional[str] = None,
        iface: Optional[str] = None,
        slowdown: int = 1,
        quiet: bool = True,
    ) -> None: ...
    @property
    def address(self) -> Optional[str]:
        """The UDP address served ("127.0.0.1:PORT"), None on an interface."""
    @property
    def iface(self) -> Optional[str]:
        """The network interface served, None on UDP."""
    @property
    def slaves(self) -> List[str]:
        """The device name of every slave, in line order."""
    @property
    def running(self) -> bool:
        """Whether the serving thread still runs."""
    def __len__(self) -> int: ...
    def stop(self) -> None:
        """Stops serving and waits for the thread; raises OxicatError if serving failed."""
    def __enter__(self) -> "Segment": ...
    def __exit__(
        self,
        exc_type: Optional[Type[BaseException]],
        exc: Optional[BaseException],
        tb: Optional[TracebackType],
    ) -> bool: ...
    def al_state(self, position: int) -> str:
        """AL state of the slave: "INIT", "PREOP", "SAFEOP", "OP" (+ "+ERR")."""
    def station_address(self, position: int) -> int:
        """The station address the master gave the slave."""
    def identity(self, position: int) -> Tuple[int, int, int]:
        """(vendor id, product code, revision) from the slave's SII EEPROM."""
    def read_outputs(self, position: int) -> bytes:
        """The outputs the master last wrote to the slave."""
    def read_inputs(self, position: int) -> bytes:
        """The inputs the slave last offered the master."""
    def write_inputs(self, position: int, data: bytes) -> None:
        """Writes the slave's inputs through its PDI, as its firmware would."""
    def set_cable(self, position: int, port: int = 0, plugged: bool = False) -> None:
        """Fault: pulls or re-plugs the cable at a port of the slave."""
    def expire_watchdog(self, position: int) -> None:
        """Fault: the slave's process-data watchdog expires now (SAFEOP+ERR 0x001B)."""
    def drop_frames(self, n: int) -> None:
        """Fault: the next ``n`` frames are lost on the master link."""
    def corrupt_next(self, position: int, port: int = 0, offset: int = 2) -> None:
        """Fault: the next frame reaching the port has byte ``offset`` inverted."""

def device_list() -> str:
    """Devices ``oxicat sim`` can serve (one "NAME  description" line each)."""
