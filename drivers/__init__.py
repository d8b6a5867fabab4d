"""Device drivers of shoveld: transports, packet parsing and device state machines.

Every driver follows :class:`drivers.base.Driver`; the daemon runs each in its
own thread and receives :class:`drivers.base.Reading` objects through a sink.
"""
