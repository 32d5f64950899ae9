"""The BlueBot's depth sensor: an MS5803 pressure sensor on I²C, read as depth (SPEC §6).

The sensor holds six factory calibration words in its PROM, guarded by a 4-bit CRC
(:func:`prom_crc`), and converts pressure (D1) and
temperature (D2) to raw 24-bit numbers on command. :func:`compensate` turns raw numbers and
calibration into pressure and temperature with the datasheet's integer arithmetic (first
order, and optionally its second-order correction below 20 °C); :class:`Ms5803` runs the
command sequence over a bus; :class:`PressureDepth` makes depth from pressure against the
surface pressure taken at start. Two models were fitted to BlueBots, with different
scalings: the 1-bar ``01BA`` and the 2-bar ``02BA`` (the robot code had a file for each).
"""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from fishswarm.bluebot.parameters import GRAVITY, BlueBot, Wiring

log = logging.getLogger(__name__)

RESET = 0x1E
PROM_READ = 0xA0
"""Address of PROM word 0 (factory data); words 1–6 (C1…C6) follow two bytes apart, and word
7 keeps the serial code with the CRC in its low four bits."""
PROM_WORDS = 8
PROM_ATTEMPTS = 3
"""How often the PROM is read before a CRC mismatch is taken for a fault, not for noise."""
CONVERT_PRESSURE = 0x40
CONVERT_TEMPERATURE = 0x50
"""Conversion commands at the lowest oversampling (256), which takes at most 0.6 ms."""
ADC_READ = 0x00
CONVERSION_TIME = 0.001
"""Time to wait for one conversion at oversampling 256, s (0.6 ms with margin)."""


@dataclass(frozen=True)
class Scaling:
    """A model's powers of two in the first-order compensation (OFF = C2·2^off +
    C4·dT/2^off_t, SENS = C1·2^sens + C3·dT/2^sens_t) and its second-order terms."""

    off: int
    off_t: int
    sens: int
    sens_t: int


MODELS = {"01BA": Scaling(16, 7, 15, 8), "02BA": Scaling(17, 6, 16, 7)}
"""The MS5803 models fitted to BlueBots and their scalings (from their datasheets)."""


class SensorError(RuntimeError):
    """The pressure sensor answered with something impossible (a bad bus or wiring)."""


def prom_crc(words: Sequence[int]) -> int:
    """The 4-bit CRC of the sensor's eight PROM words, as TE's application note AN520
    computes it: the sixteen bytes, high byte first, divided by x⁴ + x + 1, with word 7's
    low byte (where the CRC itself is kept) taken as zero.

    Args:
        words: the PROM words 0–7, each 0…65535.
    """
    if len(words) != PROM_WORDS or not all(0 <= word <= 0xFFFF for word in words):
        raise ValueError(f"the PROM has {PROM_WORDS} 16-bit words, got {list(words)}")
    remainder = 0
    for index, word in enumerate(words):
        if index == PROM_WORDS - 1:
            word &= 0xFF00
        for byte in (word >> 8, word & 0xFF):
            remainder ^= byte
            for _ in range(8):
                carry = remainder & 0x8000
                remainder = (remainder << 1) & 0xFFFF
                if carry:
                    remainder ^= 0x3000
    return remainder >> 12


@dataclass(frozen=True)
class Reading:
    """One compensated reading: pressure in Pa and temperature in °C."""

    pressure: float
    temperature: float


def compensate(
    calibration: Sequence[int],
    d1: int,
    d2: int,
    *,
    model: str = "02BA",
    second_order: bool = False,
) -> Reading:
    """Pressure and temperature from raw conversions, as the datasheet computes them.

    Args:
        calibration: the PROM words C1…C6.
        d1: raw pressure (24 bits).
        d2: raw temperature (24 bits).
        model: ``01BA`` or ``02BA``.
        second_order: apply the datasheet's correction for temperatures below 20 °C (and,
            for the 01BA, above 45 °C).

    Returns:
        Pressure (Pa; the datasheet's unit, 0.01 mbar, is 1 Pa) and temperature (°C).
    """
    scaling = MODELS.get(model)
    if scaling is None:
        raise ValueError(f"MS5803 model must be one of {', '.join(MODELS)}, got {model!r}")
    if len(calibration) != 6:
        raise ValueError(f"an MS5803 has six calibration words, got {len(calibration)}")
    c1, c2, c3, c4, c5, c6 = (int(c) for c in calibration)
    dt = d2 - (c5 << 8)
    temperature = 2000 + ((dt * c6) >> 23)
    offset = (c2 << scaling.off) + ((c4 * dt) >> scaling.off_t)
    sensitivity = (c1 << scaling.sens) + ((c3 * dt) >> scaling.sens_t)
    if second_order:
        t2, off2, sens2 = _second_order(dt, temperature, model)
        temperature -= t2
        offset -= off2
        sensitivity -= sens2
    pressure = (((d1 * sensitivity) >> 21) - offset) >> 15
    return Reading(float(pressure), temperature / 100.0)


def _second_order(dt: int, temperature: int, model: str) -> tuple[int, int, int]:
    """The datasheet's second-order terms (T2, OFF2, SENS2) of a model."""
    cold = temperature - 2000
    if model == "01BA":
        if temperature > 4500:
            hot = temperature - 4500
            return 0, 0, -((hot * hot) >> 3)
        if temperature >= 2000:
            return 0, 0, 0
        t2 = (dt * dt) >> 31
        off2 = 3 * cold * cold
        sens2 = (7 * cold * cold) >> 3
        if temperature < -1500:
            sens2 += 2 * (temperature + 1500) ** 2
        return t2, off2, sens2
    if temperature >= 2000:
        return 0, 0, 0
    t2 = (dt * dt) >> 31
    off2 = (61 * cold * cold) >> 4
    sens2 = 2 * cold * cold
    if temperature < -1500:
        off2 += 20 * (temperature + 1500) ** 2
        sens2 += 12 * (temperature + 1500) ** 2
    return t2, off2, sens2


def depth_of(pressure: float, surface_pressure: float, *, density: float) -> float:
    """Depth below the surface from the hydrostatic pressure difference, m."""
    return (pressure - surface_pressure) / (density * GRAVITY)


class I2cBus(Protocol):
    """What the sensor needs of an I²C bus (``smbus2.SMBus`` has it)."""

    def write_byte(self, i2c_addr: int, value: int) -> None: ...

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]: ...

    def close(self) -> None: ...


class Ms5803:
    """An MS5803 on an I²C bus: reset, calibration, conversions.

    Args:
        bus: the bus (``smbus2.SMBus(1)`` on a robot).
        address: the sensor's address.
        model: ``01BA`` or ``02BA``.
        second_order: apply the datasheet's low-temperature correction.
        sleep: how to wait for a conversion (tests pass a fake clock's).
    """

    def __init__(
        self,
        bus: I2cBus,
        *,
        address: int = Wiring().depth_address,
        model: str = "02BA",
        second_order: bool = True,
        sleep: Callable[[float], None] = time.sleep,
    ) -> None:
        if model not in MODELS:
            raise ValueError(f"MS5803 model must be one of {', '.join(MODELS)}, got {model!r}")
        self._bus = bus
        self._address = address
        self._model = model
        self._second_order = second_order
        self._sleep = sleep
        words = self._read_prom()
        self.calibration = words[1:7]
        """C1…C6, as :func:`compensate` takes them."""

    def _read_prom(self) -> tuple[int, ...]:
        """The PROM's eight words, once their CRC holds (read again after a mismatch: a
        disturbed transfer on a long I²C cable is more likely than a damaged chip)."""
        for attempt in range(1, PROM_ATTEMPTS + 1):
            self._bus.write_byte(self._address, RESET)
            self._sleep(0.003)  # the PROM reloads after a reset (2.8 ms)
            words = tuple(self._read_word(PROM_READ + 2 * n) for n in range(PROM_WORDS))
            if all(word in (0, 0xFFFF) for word in words[1:7]):
                raise SensorError(
                    f"no MS5803 answers at I2C address {self._address:#04x}: calibration "
                    f"words {words[1:7]} (check the wiring and `i2cdetect -y 1`)"
                )
            kept, computed = words[-1] & 0xF, prom_crc(words)
            if kept == computed:
                return words
            log.warning(
                "depth sensor: PROM read %d of %d fails its CRC (kept %#x, computed %#x)",
                attempt,
                PROM_ATTEMPTS,
                kept,
                computed,
            )
        raise SensorError(
            f"the MS5803 at I2C address {self._address:#04x} gave calibration words that "
            f"fail their CRC in {PROM_ATTEMPTS} reads (last: {words}): check the I2C wiring "
            "and pull-ups, and replace the sensor if it persists"
        )

    def _read_word(self, register: int) -> int:
        high, low = self._bus.read_i2c_block_data(self._address, register, 2)
        return (high << 8) | low

    def _convert(self, command: int) -> int:
        self._bus.write_byte(self._address, command)
        self._sleep(CONVERSION_TIME)
        first, second, third = self._bus.read_i2c_block_data(self._address, ADC_READ, 3)
        return (first << 16) | (second << 8) | third

    def read(self) -> Reading:
        """Convert pressure and temperature, and compensate them."""
        d1 = self._convert(CONVERT_PRESSURE)
        d2 = self._convert(CONVERT_TEMPERATURE)
        if d1 == 0 or d2 == 0:
            raise SensorError("the MS5803 returned an empty conversion (read too early?)")
        return compensate(
            self.calibration, d1, d2, model=self._model, second_order=self._second_order
        )

    def close(self) -> None:
        """Release the bus."""
        self._bus.close()


class PressureReader(Protocol):
    """Anything that reads pressure (:class:`Ms5803`, or a simulated sensor)."""

    def read(self) -> Reading: ...

    def close(self) -> None: ...


SURFACE_FILE = "surface-pressure.json"
"""Where a robot keeps the surface pressure it measured, in its state folder."""
SURFACE_KEPT = 6 * 3600.0
"""How long a kept surface pressure is trusted, s: the weather moves the air's pressure by
up to about 1 hPa an hour, which reads as 1 cm of depth."""
SURFACE_TOLERANCE = 200.0
"""A start reading this much (Pa, 2 cm of water) above the kept surface pressure means the
robot started under water."""


class PressureDepth:
    """Depth from a pressure sensor: against the surface pressure, the mean of a few
    readings at start (the robot at the surface). Implements the ``DepthSensor`` port.

    A robot whose process restarts in mid-dive would take its depth then for the surface.
    Given a ``surface_file``, the surface pressure measured at a start at the surface is
    kept there, and a later start that reads more than :data:`SURFACE_TOLERANCE` above it,
    within :data:`SURFACE_KEPT`, goes on from the kept one instead.

    Args:
        sensor: the pressure sensor.
        density: the water's density, kg/m³.
        surface_samples: readings averaged for the surface pressure.
        surface_file: where to keep the surface pressure across restarts (None: nowhere).
        clock: wall-clock time, s (for the kept value's age).
    """

    def __init__(
        self,
        sensor: PressureReader,
        *,
        density: float = BlueBot().water_density,
        surface_samples: int = 5,
        surface_file: Path | None = None,
        clock: Callable[[], float] = time.time,
    ) -> None:
        if surface_samples < 1:
            raise ValueError("surface_samples must be at least 1")
        self._sensor = sensor
        self._density = density
        readings = [sensor.read().pressure for _ in range(surface_samples)]
        here = sum(readings) / len(readings)
        kept = None if surface_file is None else _kept_surface(surface_file, clock())
        self.resumed = kept is not None and here > kept + SURFACE_TOLERANCE
        """Whether the robot started under water and goes on from the kept surface."""
        if self.resumed:
            assert kept is not None
            self.surface_pressure = kept
            log.warning(
                "depth sensor: %.0f Pa at start, %.2f m below the surface kept in %s: "
                "started under water, depth measured from the kept surface",
                here, depth_of(here, kept, density=density), surface_file,
            )  # fmt: skip
        else:
            self.surface_pressure = here
            if surface_file is not None:
                _keep_surface(surface_file, here, clock())

    def read_depth(self) -> float:
        """Depth below the surface, m (positive down)."""
        pressure = self._sensor.read().pressure
        return depth_of(pressure, self.surface_pressure, density=self._density)

    def close(self) -> None:
        """Release the sensor."""
        self._sensor.close()


def _kept_surface(path: Path, now: float) -> float | None:
    """The surface pressure kept in ``path`` if it is recent enough, Pa (None: none)."""
    try:
        kept = json.loads(path.read_text())
        pressure, taken = float(kept["pressure"]), float(kept["time"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    fresh = 0.0 <= now - taken <= SURFACE_KEPT and math.isfinite(pressure) and pressure > 0
    return pressure if fresh else None


def _keep_surface(path: Path, pressure: float, now: float) -> None:
    """Keep the surface pressure in ``path`` (written whole, then moved into place, so that
    a robot switched off meanwhile leaves the old value or the new one, never half)."""
    partial = path.with_suffix(".partial")
    try:
        partial.write_text(json.dumps({"pressure": pressure, "time": now}))
        partial.replace(path)
    except OSError as error:
        log.warning("depth sensor: cannot keep the surface pressure in %s: %s", path, error)


def i2c_depth_sensor(
    *,
    wiring: Wiring = Wiring(),
    model: str = "02BA",
    density: float = BlueBot().water_density,
    surface_file: Path | None = None,
) -> PressureDepth:
    """The robot's depth sensor over I²C (needs ``smbus2``, from the ``robot`` extra),
    keeping its surface pressure in ``surface_file`` (see :class:`PressureDepth`).

    Raises:
        SensorError: no sensor answers.
        ImportError: smbus2 is not installed.
    """
    try:
        from smbus2 import SMBus
    except ImportError as error:
        raise ImportError(
            "the depth sensor needs smbus2: on Raspberry Pi OS apt install python3-smbus2 "
            "(deploy/ does), elsewhere pip install -e '.[robot]'"
        ) from error
    bus = SMBus(wiring.depth_bus)
    try:
        return PressureDepth(
            Ms5803(bus, address=wiring.depth_address, model=model),
            density=density,
            surface_file=surface_file,
        )
    except BaseException:
        bus.close()
        raise
