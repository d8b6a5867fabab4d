"""The shovel's service: drivers, fixed-rate loop, engine, pass log, Zenoh (issue 4).

See ``docs/daemon.md`` for the threads and data flow, ``docs/config.md`` for the
configuration file and ``docs/zenoh.md`` for the topics.
"""
