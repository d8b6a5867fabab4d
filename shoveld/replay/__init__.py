"""Replay: the daemon fed from recordings instead of live devices, through the same
``Service`` and ``Engine`` as live (one engine, several feeders).

* :mod:`shoveld.replay.service`: the service built on a capture folder, paced on the
  drivers' virtual hardware (``replay_service``) or as fast as the machine allows
  (``fast_replay_service``), and the run that plays it (``ReplayRun``).
* :mod:`shoveld.replay.sync`: every recorded device as its real driver on in-memory
  transports, stepped by the loop's clock (``SyncReplay``).
* :mod:`shoveld.replay.bulk`: the fast replay's front end, each device's recording
  decoded ahead of the ticks and the samples built with numpy (``BulkFeed``).
* :mod:`shoveld.replay.table`: readings made from a signals table, for tests and
  benches of everything after the drivers (``TableFeed``).

The capture files themselves (their format, readers, and the recorded transports the
drivers talk to) are in :mod:`drivers.capture`; each driver's bulk decoding of a
recording is its ``span`` module. Nothing here is imported by the live daemon.
"""
