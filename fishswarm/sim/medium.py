"""The broadcast medium of the simulation: who receives a fish's broadcast, and where from.

On robots the medium is physical (LED signals); in simulation the channel actor stands in
for it with this pure model: a broadcast reaches every other fish within range, each
delivery lost with a seeded probability, and carries the sender's position as the receiver
sees it (body frame, no id).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from fishswarm.behaviors.core import Heard, Inbox, Outbox, inbox_of
from fishswarm.bluebot.vision import to_body

FloatArray = NDArray[np.float64]


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

    Returns:
        Deliveries ordered by receiver, then by broadcast.
    """
    result: list[Reception] = []
    if not senders:
        return result
    sender_index = np.asarray(senders, dtype=np.intp)
    relative = position[sender_index][None, :, :] - position[:, None, :]
    distance = np.linalg.norm(relative, axis=2)
    reach = distance <= channel_range
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


def deliver(
    position: FloatArray,
    yaw: FloatArray,
    outbox: Outbox,
    *,
    channel_range: float,
    loss: float,
    rngs: Sequence[np.random.Generator],
) -> Inbox:
    """The inboxes of N fish after the broadcasts of ``outbox`` (rows of the same fish).

    The same receptions, in the same order and with the same random draws, as the channel
    actor makes of the same broadcasts: senders in row (fish-id) order.
    """
    senders = np.flatnonzero(outbox.mask).tolist()
    heard: list[list[Heard]] = [[] for _ in range(position.shape[0])]
    for reception in receptions(
        position, yaw, senders, channel_range=channel_range, loss=loss, rngs=rngs
    ):
        sender = reception.sender
        heard[reception.receiver].append(
            (int(outbox.kind[sender]), outbox.values[sender], reception.sender_position)
        )
    return inbox_of(heard)
