"""fishswarm: BlueBot robot-fish swarms as async actors over Eclipse Zenoh."""

__version__ = "0.1.0"
