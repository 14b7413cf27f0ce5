"""ecmxf: Python client for ecmxfd, the ECM-XF EtherCAT master daemon.

    import ecmxf
    with ecmxf.connect() as c:
        print(c.slaves())
        print(hex(c.sdo_read(1, 0x1018, 1)))
        for sample in c.stream_inputs(duration=1.0):
            print(sample.seq, sample)

The generated gRPC stubs of the whole API are in ``ecmxf.v1``.
"""

from .client import Client, Entry, Event, Layout, Lease, Sample, Slave, connect, default_socket
from . import errors
from .errors import *  # noqa: F403 (the exceptions, listed in errors.__all__)

__all__ = ["connect", "default_socket", "Client", "Slave", "Entry", "Layout", "Sample", "Event", "Lease"] + errors.__all__
__version__ = "0.1.0"
