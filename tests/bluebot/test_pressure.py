"""The MS5803 depth sensor: the datasheet's arithmetic, the command sequence on the bus, and
depth from pressure."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fishswarm.bluebot.pressure import (
    ADC_READ,
    CONVERT_PRESSURE,
    CONVERT_TEMPERATURE,
    RESET,
    Ms5803,
    PressureDepth,
    Reading,
    SensorError,
    compensate,
    depth_of,
    prom_crc,
)

# The worked example of TE's 2-bar sensors' datasheets (MS5803-02BA, MS5607-02BA03 p. 8).
EXAMPLE_CALIBRATION = (46372, 43981, 29059, 27842, 31553, 28165)
EXAMPLE_D1, EXAMPLE_D2 = 6465444, 8077636
# As a chip would hold it: factory word 0, C1…C6, serial code 0x123 and the CRC 0x2.
EXAMPLE_PROM = (0x0064, *EXAMPLE_CALIBRATION, 0x1232)


def test_the_datasheets_worked_example() -> None:
    # dT = 68, TEMP = 2000 (20.00 °C), OFF = 5 764 707 214, SENS = 3 039 050 829,
    # P = 110 002 (1100.02 mbar).
    reading = compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, EXAMPLE_D2, model="02BA")
    assert reading == Reading(110002.0, 20.0)
    # At exactly 20 °C the second-order correction changes nothing.
    assert compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, EXAMPLE_D2, second_order=True) == reading


def test_the_one_bar_models_scaling_by_hand() -> None:
    # 01BA: OFF = C2·2^16 + C4·dT/2^7 = 2 882 338 816 + 14 791 = 2 882 353 607;
    # SENS = C1·2^15 + C3·dT/2^8 = 1 519 517 696 + 7 718 = 1 519 525 414;
    # D1·SENS/2^21 = 4 684 642 062; P = (4 684 642 062 − OFF)/2^15 = 55 001 (550.01 mbar).
    reading = compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, EXAMPLE_D2, model="01BA")
    assert reading == Reading(55001.0, 20.0)


def test_cold_water_gets_the_second_order_correction() -> None:
    # dT = −297 841: TEMP = 2000 + dT·C6/2^23 = 999 (9.99 °C).
    d2 = (31553 << 8) - 297841
    first = compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="02BA")
    assert first == Reading(107594.0, 9.99)
    # T2 = dT²/2^31 = 41; OFF2 = 61·1001²/16 = 3 820 128; SENS2 = 2·1001² = 2 004 002;
    # P falls by (D1·SENS2/2^21 − OFF2)/2^15 = (6 178 178 − 3 820 128)/32 768 ≈ 72.
    second = compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="02BA", second_order=True)
    assert second == Reading(107522.0, 9.58)


def test_the_one_bar_models_second_order_correction_by_hand() -> None:
    # Cold, 9.99 °C (dT = −297 841, TEMP = 999): T2 = dT²/2^31 = 41;
    # OFF2 = 3·1001² = 3 006 003; SENS2 = 7·1001²/2^3 = 876 750. OFF = 2 817 553 744 and
    # SENS = 1 485 709 252 give P = 53 797 before, 53 806 after.
    d2 = (31553 << 8) - 297841
    assert compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="01BA") == Reading(53797.0, 9.99)
    cold = compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="01BA", second_order=True)
    assert cold == Reading(53806.0, 9.58)
    # Hot, 85 °C (dT = 1 936 000, TEMP = 8 500): above 45 °C, SENS2 = −(8500 − 4500)²/2^3
    # = −2 000 000, so SENS grows from 1 739 276 383 to 1 741 276 383; with OFF =
    # 3 303 449 066, P = 62 825 before, 63 014 after; T unchanged.
    d2 = (31553 << 8) + 1_936_000
    assert compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="01BA") == Reading(62825.0, 85.0)
    hot = compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="01BA", second_order=True)
    assert hot == Reading(63014.0, 85.0)


def test_below_minus_15_degrees_both_models_add_their_last_terms() -> None:
    # dT = −1 100 000: TEMP = −1 694 (−16.94 °C), T2 = 563; TEMP − 2000 = −3 694 and
    # TEMP + 1500 = −194.
    d2 = (31553 << 8) - 1_100_000
    # 01BA: OFF2 = 3·3694² = 40 936 908; SENS2 = 7·3694²/2^3 + 2·194² = 12 015 203;
    # P = 50 555 before (OFF 2 643 071 628, SENS 1 394 654 805), 50 674 after.
    one_bar = compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="01BA", second_order=True)
    assert one_bar == Reading(50674.0, -22.57)
    # 02BA: OFF2 = 61·3694²/2^4 + 20·194² = 52 776 707; SENS2 = 2·3694² + 12·194²
    # = 27 742 904; P = 101 110 before (OFF 5 286 143 257, SENS 2 789 309 610), 100 111 after.
    assert compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="02BA") == Reading(
        101110.0, -16.94
    )
    two_bar = compensate(EXAMPLE_CALIBRATION, EXAMPLE_D1, d2, model="02BA", second_order=True)
    assert two_bar == Reading(100111.0, -22.57)


def test_bad_models_and_calibrations_are_refused() -> None:
    with pytest.raises(ValueError, match="01BA, 02BA"):
        compensate(EXAMPLE_CALIBRATION, 1, 1, model="14BA")
    with pytest.raises(ValueError, match="six calibration words"):
        compensate(EXAMPLE_CALIBRATION[:5], 1, 1)


@given(st.floats(0.0, 10.0), st.floats(90_000.0, 110_000.0))
def test_depth_is_the_hydrostatic_pressure_difference(depth: float, surface: float) -> None:
    pressure = surface + 998.0 * 9.81 * depth
    assert depth_of(pressure, surface, density=998.0) == pytest.approx(depth, abs=1e-9)


class SimulatedChip:
    """An MS5803 as its I²C bus sees it: PROM words, conversions on command, the ADC read
    back once a conversion has finished."""

    def __init__(self, prom: tuple[int, ...], d1: int, d2: int, address: int = 0x77):
        self.prom = {0xA0 + 2 * n: word for n, word in enumerate(prom)}
        self.raw = {CONVERT_PRESSURE: d1, CONVERT_TEMPERATURE: d2}
        self.address = address
        self.adc = 0
        self.commands: list[int] = []
        self.closed = False

    def write_byte(self, i2c_addr: int, value: int) -> None:
        if i2c_addr != self.address:
            return  # not for this chip
        self.commands.append(value)
        self.adc = self.raw.get(value, 0)

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        if i2c_addr != self.address:
            return [0xFF] * length  # nobody answers: the bus floats high
        if register == ADC_READ:
            value, self.adc = self.adc, 0  # read once, as the chip does
            return [(value >> 16) & 0xFF, (value >> 8) & 0xFF, value & 0xFF][:length]
        word = self.prom[register]
        return [word >> 8, word & 0xFF][:length]

    def close(self) -> None:
        self.closed = True


def test_the_driver_reads_the_chip_in_the_datasheets_order() -> None:
    chip = SimulatedChip(EXAMPLE_PROM, EXAMPLE_D1, EXAMPLE_D2)
    waits: list[float] = []
    sensor = Ms5803(chip, model="02BA", sleep=waits.append)
    assert sensor.calibration == EXAMPLE_CALIBRATION
    assert sensor.read() == Reading(110002.0, 20.0)
    assert chip.commands == [RESET, CONVERT_PRESSURE, CONVERT_TEMPERATURE]
    assert waits[0] >= 0.0028 and all(w >= 0.0006 for w in waits[1:])
    sensor.close()
    assert chip.closed


def test_a_missing_sensor_is_named() -> None:
    chip = SimulatedChip(EXAMPLE_PROM, EXAMPLE_D1, EXAMPLE_D2, address=0x76)
    with pytest.raises(SensorError, match="no MS5803 answers at I2C address 0x77"):
        Ms5803(chip, sleep=lambda _: None)  # the chip answers at 0x76, we ask 0x77


def test_a_bus_held_low_is_no_sensor_though_its_zeros_pass_the_crc() -> None:
    # SDA stuck low reads every PROM word as 0, and 0 is the CRC of eight zero words.
    chip = SimulatedChip((0,) * 8, EXAMPLE_D1, EXAMPLE_D2)
    assert prom_crc((0,) * 8) == 0
    with pytest.raises(SensorError, match="no MS5803 answers at I2C address 0x77"):
        Ms5803(chip, sleep=lambda _: None)


@pytest.mark.parametrize("word", [0x0000, 0xFFFF])
def test_a_calibration_word_of_all_zeros_or_ones_is_still_a_calibration(word: int) -> None:
    # Only a PROM whose six calibration words are all 0 or all 1 bits is taken for no chip.
    prom = [*EXAMPLE_PROM]
    prom[4] = word
    prom[7] = (prom[7] & 0xFFF0) | prom_crc(prom)
    sensor = Ms5803(SimulatedChip(tuple(prom), EXAMPLE_D1, EXAMPLE_D2), sleep=lambda _: None)
    assert sensor.calibration == tuple(prom[1:7])


@pytest.mark.parametrize("empty", [CONVERT_PRESSURE, CONVERT_TEMPERATURE])
def test_an_empty_conversion_is_a_sensor_error_not_a_reading(empty: int) -> None:
    chip = SimulatedChip(EXAMPLE_PROM, EXAMPLE_D1, EXAMPLE_D2)
    chip.raw[empty] = 0  # read before the conversion finished
    sensor = Ms5803(chip, model="02BA", sleep=lambda _: None)
    with pytest.raises(SensorError, match="empty conversion"):
        sensor.read()


def test_the_prom_crc_of_te_application_note_an520() -> None:
    # AN520's own check of its CRC code: these eight words give 0xB.
    words = (0x3132, 0x3334, 0x3536, 0x3738, 0x3940, 0x4142, 0x4344, 0x4500)
    assert prom_crc(words) == 0xB
    assert prom_crc(EXAMPLE_PROM) == EXAMPLE_PROM[7] & 0xF
    with pytest.raises(ValueError, match="8 16-bit words"):
        prom_crc(words[:7])
    with pytest.raises(ValueError, match="8 16-bit words"):
        prom_crc((*words[:7], 0x10000))


def test_the_prom_crc_takes_any_16_bit_word_and_only_those() -> None:
    assert prom_crc((0x0000, 0xFFFF, 0x0000, 0xFFFF, 0x0000, 0xFFFF, 0x0000, 0xFF00)) == 0xC
    with pytest.raises(ValueError, match="8 16-bit words"):
        prom_crc((-1, *EXAMPLE_PROM[1:]))


@given(st.integers(0, 8 * 16 - 9))
def test_the_crc_catches_any_one_flipped_bit_and_ignores_its_own_nibble(bit: int) -> None:
    # x⁴ + x + 1 has more than one term, so no single flipped bit divides by it: every
    # one-bit error among the 120 bits it covers (not word 7's low byte) changes the CRC.
    word, place = divmod(bit, 16)
    if word == 7:
        place += 8  # word 7's high byte: its low byte holds the CRC
    flipped = list(EXAMPLE_PROM)
    flipped[word] ^= 1 << place
    assert prom_crc(flipped) != prom_crc(EXAMPLE_PROM)
    assert prom_crc((*EXAMPLE_PROM[:7], EXAMPLE_PROM[7] ^ (bit & 0xFF))) == prom_crc(EXAMPLE_PROM)


class DisturbedChip(SimulatedChip):
    """A chip whose first ``disturbed`` PROM reads come back with one bit of C3 flipped (a
    transfer disturbed on the cable)."""

    def __init__(self, disturbed: int) -> None:
        super().__init__(EXAMPLE_PROM, EXAMPLE_D1, EXAMPLE_D2)
        self.disturbed = disturbed

    def read_i2c_block_data(self, i2c_addr: int, register: int, length: int) -> list[int]:
        data = super().read_i2c_block_data(i2c_addr, register, length)
        if register == 0xA6 and self.commands.count(RESET) <= self.disturbed:
            data[1] ^= 0x10
        return data


def test_a_prom_read_that_fails_its_crc_is_read_again(caplog: pytest.LogCaptureFixture) -> None:
    chip = DisturbedChip(disturbed=2)
    with caplog.at_level("WARNING"):
        sensor = Ms5803(chip, model="02BA", sleep=lambda _: None)
    assert sensor.calibration == EXAMPLE_CALIBRATION  # the third read, undisturbed
    assert chip.commands == [RESET] * 3
    assert "PROM read 1 of 3 fails its CRC" in caplog.text
    assert "PROM read 2 of 3 fails its CRC" in caplog.text
    assert sensor.read() == Reading(110002.0, 20.0)


def test_a_prom_that_always_fails_its_crc_is_a_sensor_error() -> None:
    chip = DisturbedChip(disturbed=3)
    with pytest.raises(SensorError, match=r"fail their CRC in 3 reads.*check the I2C wiring"):
        Ms5803(chip, model="02BA", sleep=lambda _: None)


class StepPressure:
    """A pressure sensor whose readings follow a list."""

    def __init__(self, pressures: list[float]) -> None:
        self.pressures = iter(pressures)

    def read(self) -> Reading:
        return Reading(next(self.pressures), 20.0)

    def close(self) -> None:
        pass


def test_depth_is_measured_from_the_surface_pressure_taken_at_start() -> None:
    rho_g = 998.0 * 9.81
    # Five readings at the surface (mean 100 000 Pa), then 0.5 m down.
    sensor = StepPressure([99_990.0, 100_010.0, 100_000.0, 99_995.0, 100_005.0,
                           100_000.0 + 0.5 * rho_g])  # fmt: skip
    depth = PressureDepth(sensor, density=998.0)
    assert depth.surface_pressure == 100_000.0
    assert depth.read_depth() == pytest.approx(0.5)


RHO_G = 998.0 * 9.81


def surface_then(depth: float, surface: float = 100_000.0) -> StepPressure:
    """Five readings at start with the robot ``depth`` m below a surface at ``surface``
    Pa, then one at the same depth."""
    here = surface + depth * RHO_G
    return StepPressure([here] * 6)


def test_a_restart_in_mid_dive_goes_on_from_the_kept_surface(tmp_path: Path) -> None:
    kept = tmp_path / "surface-pressure.json"
    clock = [1_000.0]
    # The first start, at the surface: its pressure is kept.
    first = PressureDepth(
        surface_then(0.0), density=998.0, surface_file=kept, clock=lambda: clock[0]
    )
    assert not first.resumed and first.surface_pressure == 100_000.0
    assert json.loads(kept.read_text()) == {"pressure": 100_000.0, "time": 1_000.0}
    # Restarted an hour later 0.5 m down: depth from the kept surface, not 0.
    clock[0] += 3_600.0
    again = PressureDepth(
        surface_then(0.5), density=998.0, surface_file=kept, clock=lambda: clock[0]
    )
    assert again.resumed and again.surface_pressure == 100_000.0
    assert again.read_depth() == pytest.approx(0.5)
    assert json.loads(kept.read_text())["time"] == 1_000.0  # a dive's reading is not kept


@pytest.mark.parametrize(
    ("age", "depth", "weather", "resumed"),
    [
        (3_600.0, 0.01, 0.0, False),  # within 2 cm of the kept surface: at the surface
        (3_600.0, 0.0, -300.0, False),  # the air's pressure fell: the surface is lower
        (7 * 3_600.0, 0.5, 0.0, False),  # kept too long ago: not trusted
        (-60.0, 0.5, 0.0, False),  # kept "in the future" (a clock set back): not trusted
    ],
)
def test_a_start_at_the_surface_or_an_old_surface_takes_it_anew(
    tmp_path: Path, age: float, depth: float, weather: float, resumed: bool
) -> None:
    kept = tmp_path / "surface-pressure.json"
    kept.write_text(json.dumps({"pressure": 100_000.0, "time": 0.0}))
    sensor = surface_then(depth, surface=100_000.0 + weather)
    started = PressureDepth(sensor, density=998.0, surface_file=kept, clock=lambda: age)
    assert started.resumed is resumed
    assert started.surface_pressure == pytest.approx(100_000.0 + weather + depth * RHO_G)
    assert json.loads(kept.read_text())["time"] == age  # taken anew, and kept


@pytest.mark.parametrize(
    "content",
    [
        "",
        "{not json",
        '{"pressure": "high", "time": 0}',
        "[]",
        '{"pressure": 0.0, "time": 0}',  # no surface has no pressure
        '{"pressure": -5.0, "time": 0}',
    ],
)
def test_a_damaged_kept_surface_is_taken_anew(tmp_path: Path, content: str) -> None:
    kept = tmp_path / "surface-pressure.json"
    kept.write_text(content)
    started = PressureDepth(surface_then(0.5), density=998.0, surface_file=kept, clock=lambda: 10.0)
    assert not started.resumed
    assert json.loads(kept.read_text()) == {"pressure": started.surface_pressure, "time": 10.0}


def test_the_surface_needs_at_least_one_reading() -> None:
    with pytest.raises(ValueError, match="surface_samples must be at least 1"):
        PressureDepth(StepPressure([100_000.0]), surface_samples=0)
    one = PressureDepth(StepPressure([100_000.0, 100_000.0 + RHO_G]), surface_samples=1)
    assert one.surface_pressure == 100_000.0
