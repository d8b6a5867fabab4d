"""shoveld: onboard payload monitor for electric cable (rope) mining shovels."""

__version__ = "0.1.0"
