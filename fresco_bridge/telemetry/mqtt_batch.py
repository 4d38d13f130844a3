"""QoS-0 telemetry in batches: many MQTT PUBLISH packets, one socket write.

paho writes every queued packet with its own ``send``. At one message per step that is a
syscall per step and, when the integrator shares the process (the demo), a GIL hand-off per
step, which cost the demo ~50 % of its speed. QoS-0 PUBLISH packets concatenated are still a
valid MQTT byte stream, so the drain encodes the steps gathered since its last pass and hands
them to paho as one packet: paho's writer sends it at once (resuming partial writes) and
marks the ``MQTTMessageInfo`` published when all of it is out. This relies on paho's
``_packet_queue`` and ``_sock`` (paho-mqtt is pinned) and on aiomqtt's MQTT 3.1.1 default.
"""

from __future__ import annotations

import aiomqtt
from paho.mqtt.client import (
    MQTT_ERR_AGAIN,
    MQTT_ERR_NO_CONN,
    MQTT_ERR_SUCCESS,
    PUBLISH,
    Client,
    MQTTMessageInfo,
    MQTTv311,
)

__all__ = ["Qos0Batch", "hand_to_paho"]


class Qos0Batch:
    """QoS-0 MQTT 3.1.1 PUBLISH packets (no retain, no dup), encoded back to back."""

    __slots__ = ("buf", "count")

    def __init__(self) -> None:
        self.buf = bytearray()
        self.count = 0

    def add(self, topic: str, payload: bytes) -> None:
        t = topic.encode()
        remaining = 2 + len(t) + len(payload)
        buf = self.buf
        buf.append(PUBLISH)
        while True:  # "remaining length": 7 bits per byte, high bit = more follows
            byte, remaining = remaining & 0x7F, remaining >> 7
            buf.append(byte | 0x80 if remaining else byte)
            if not remaining:
                break
        buf += len(t).to_bytes(2, "big")
        buf += t
        buf += payload
        self.count += 1

    def take(self) -> tuple[bytearray, int]:
        """The encoded packets and their number; the batch is empty afterwards."""
        data, n = self.buf, self.count
        self.buf, self.count = bytearray(), 0
        return data, n


def hand_to_paho(paho: Client, data: bytearray) -> MQTTMessageInfo:
    """Queue ``data`` (whole PUBLISH packets) on paho's writer; raises MqttCodeError if the
    client is not connected or speaks a protocol these packets do not fit."""
    if paho._protocol != MQTTv311:
        raise aiomqtt.MqttCodeError(MQTT_ERR_NO_CONN, "batched telemetry needs MQTT 3.1.1")
    if paho._sock is None:
        raise aiomqtt.MqttCodeError(MQTT_ERR_NO_CONN, "Could not publish message")
    info = MQTTMessageInfo(0)  # paho never uses mid 0, so no pending publish matches it
    rc = paho._packet_queue(PUBLISH, data, 0, 0, info)
    if rc not in (MQTT_ERR_SUCCESS, MQTT_ERR_AGAIN):
        raise aiomqtt.MqttCodeError(rc, "Could not publish message")
    return info
