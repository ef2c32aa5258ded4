"""Reads vic MCAP recordings with the official `mcap` Python package and checks every message.

Usage: python check_recording.py FILE.mcap [FILE.mcap ...]

For each file: every channel is `json` with a `jsonschema` schema, every message decodes as JSON
and holds every key its schema requires. Prints one JSON object: per file, the messages per
topic, the first tick whose external torque is the test pulse (0.25, -0.125) on the tick or
state channel, and the metadata records. Exits 1 on the first message that does not conform.
"""

import json
import sys

from mcap.reader import make_reader

PULSE = [0.25, -0.125]


def check(path):
    counts = {}
    first_pulse = None
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            where = f"{path}: {channel.topic} message {message.sequence}"
            if channel.message_encoding != "json" or schema is None or schema.encoding != "jsonschema":
                raise SystemExit(f"{where}: not JSON with a JSON Schema")
            required = json.loads(schema.data).get("required", [])
            msg = json.loads(message.data)
            missing = [k for k in required if k not in msg]
            if missing:
                raise SystemExit(f"{where}: missing {missing}")
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if (
                first_pulse is None
                and channel.topic in ("/board/tick", "/state")
                and msg["tau_ext"] == PULSE
            ):
                first_pulse = msg["tick"]
        f.seek(0)
        metadata = {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}
    return {"counts": counts, "first_pulse_tick": first_pulse, "metadata": metadata}


if __name__ == "__main__":
    print(json.dumps({p: check(p) for p in sys.argv[1:]}))
