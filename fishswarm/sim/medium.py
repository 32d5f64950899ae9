"""The broadcast medium of the simulation: who receives a fish's broadcast, and where from.

On robots the medium is physical (LED signals); in simulation the channel actor stands in
for it with this pure model: a broadcast reaches every other fish within range, each
delivery lost with a seeded probability, and carries the sender's position as the receiver
sees it (body frame, no id).

With formation flags by light (``flag_medium = "light"``), the medium is the robots' own:
only a formation flag that says its sender holds its place travels, reduced to that one bit
(:func:`one_bit`), and it reaches the fish that see its sender — within visual range,
outside their blind spot, not hidden by another body — instead of every fish within the
channel's range. By beacon (``"beacon"``) the same one bit reaches every fish within the
channel's range, whether it sees the sender or not.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import Heard, Inbox, Outbox, inbox_of
from fishswarm.behaviors.formation import FORMATION_KIND, flag_by_light
from fishswarm.bluebot.vision import Vision, perceive, to_body
from fishswarm.protocols.messages import FLASHING, FormationFlag

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class Reception:
    """One delivery: receiver and sender as batch indices, which broadcast (its index in the
    ``senders`` list), and the sender's body-frame position."""

    receiver: int
    sender: int
    broadcast: int
    sender_position: FloatArray


def receptions(
    position: FloatArray,
    yaw: FloatArray,
    senders: Sequence[int],
    *,
    channel_range: float,
    loss: float,
    rngs: Sequence[np.random.Generator],
    sight: Vision | None = None,
) -> list[Reception]:
    """Deliveries of one tick's broadcasts.

    Args:
        position: (N, 3) positions of all fish, m.
        yaw: (N,) yaws, rad.
        senders: batch index of the sender of each broadcast, in sending order.
        channel_range: how far a broadcast carries, m.
        loss: probability that one delivery is lost.
        rngs: one generator per fish (receiver), used only when ``loss`` > 0; each receiver
            draws once per broadcast in range, in order, so results do not depend on others.
        sight: broadcasts by light: a broadcast reaches the fish that see its sender with
            this vision model (its noise left out), not those within ``channel_range``.

    Returns:
        Deliveries ordered by receiver, then by broadcast.
    """
    result: list[Reception] = []
    if not senders:
        return result
    sender_index = np.asarray(senders, dtype=np.intp)
    relative = position[sender_index][None, :, :] - position[:, None, :]
    if sight is None:
        reach = np.linalg.norm(relative, axis=2) <= channel_range
    else:
        reach = seeing(position, yaw, vision=sight)[:, sender_index]
    reach[sender_index, np.arange(sender_index.size)] = False
    body = to_body(np.ascontiguousarray(relative), yaw)
    for receiver in range(position.shape[0]):
        for column in np.flatnonzero(reach[receiver]):
            if loss > 0 and rngs[receiver].uniform() < loss:
                continue
            result.append(
                Reception(receiver, int(sender_index[column]), int(column), body[receiver, column])
            )
    return result


def seeing(position: FloatArray, yaw: FloatArray, *, vision: Vision) -> BoolArray:
    """Which fish sees which: (N, N), row the viewer, column the fish seen (range, blind
    spot and occlusion of ``vision``; its position noise, which moves no one out of sight,
    left out)."""
    perceived = perceive(position, yaw, vision=vision.exact())
    seen = np.zeros((position.shape[0], position.shape[0]), dtype=np.bool_)
    viewers, rows = np.nonzero(perceived.mask)
    seen[viewers, perceived.index[viewers, rows]] = True
    return seen


def flashes_shown(lights: IntArray | None, *, time_mode: str) -> bool:
    """Whether a snapshot's ``lights`` (DARK, STEADY or FLASHING per fish; None: all
    steady) hold robots' flashes for the channel to show simulated fish: any flash, unless
    the run is in jitter mode, which delivers nothing. The world then waits for the
    channel's report, and the channel reports, whoever is there to be shown."""
    return lights is not None and time_mode != "jitter" and bool((lights == FLASHING).any())


def travelling(
    kinds: Sequence[int], values: Sequence[IntArray], *, one_bit_flags: bool
) -> list[tuple[int, IntArray]]:
    """Which of some broadcasts (their kinds and numbers) travel, and what each says, in
    order: (position among them, numbers). All, as sent; with ``one_bit_flags`` only the
    formation flags of fish that hold their place, reduced to that (:func:`one_bit`)."""
    if not one_bit_flags:
        return list(enumerate(values))
    said = [one_bit(kind, numbers) for kind, numbers in zip(kinds, values, strict=True)]
    return [(n, numbers) for n, numbers in enumerate(said) if numbers is not None]


def one_bit(kind: int, values: IntArray) -> IntArray | None:
    """What a one-bit flag (light, a beacon) says of a broadcast: for a formation flag that
    says its sender holds its place, the numbers of that flag reduced to it
    (:func:`~fishswarm.behaviors.formation.flag_by_light`: the shape and orientation kept —
    a school's fish share them, where a robot gives the flags it sees its own fish's — no
    slot, hops, effort or swap); None for any other broadcast, which is not sent."""
    if kind != FORMATION_KIND:
        return None
    # A decision's and a decoded broadcast's formation numbers are a flag, checked.
    flag = FormationFlag.from_values(values)
    return flag_by_light(flag).values() if flag.joined else None


def deliver(
    position: FloatArray,
    yaw: FloatArray,
    outbox: Outbox,
    *,
    channel_range: float,
    loss: float,
    rngs: Sequence[np.random.Generator],
    sight: Vision | None = None,
    one_bit_flags: bool = False,
) -> Inbox:
    """The inboxes of N fish after the broadcasts of ``outbox`` (rows of the same fish).

    The same receptions, in the same order and with the same random draws, as the channel
    actor makes of the same broadcasts: senders in row (fish-id) order. With ``sight``
    broadcasts reach the fish that see their sender (:func:`receptions`); with
    ``one_bit_flags`` only formation flags of fish that hold their place travel, reduced to that.
    """
    rows = np.flatnonzero(outbox.mask).tolist()
    said = travelling(
        [int(outbox.kind[row]) for row in rows],
        [outbox.values[row] for row in rows],
        one_bit_flags=one_bit_flags,
    )
    sent = {rows[n]: values for n, values in said}
    senders = list(sent)
    heard: list[list[Heard]] = [[] for _ in range(position.shape[0])]
    for reception in receptions(
        position, yaw, senders, channel_range=channel_range, loss=loss, rngs=rngs, sight=sight
    ):
        sender = reception.sender
        heard[reception.receiver].append(
            (int(outbox.kind[sender]), sent[sender], reception.sender_position)
        )
    return inbox_of(heard)
