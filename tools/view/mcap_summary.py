#!/usr/bin/env python3
"""An independent reader of omnitrack-view's MCAP files: the official `mcap` package from PyPI.

In: the path of an MCAP file. Out, on standard output, one JSON object: per topic its schema
name, schema encoding, message encoding and message count, counted by reading every message
(not from the summary), each message decoded as JSON; the summary's own statistics beside them,
so that a test can compare the two; and the first `foxglove.PoseInFrame`'s position. Exit 1
with one line on standard error when the file does not read or a message is not JSON.

Used by tests/live_view.rs, in a venv with `mcap` (pinned there).
"""
import json
import sys

from mcap.reader import make_reader


def main(path):
    topics = {}
    first_pose = None
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for schema, channel, message in reader.iter_messages():
            t = topics.setdefault(
                channel.topic,
                {
                    "schema": schema.name if schema else None,
                    "schema_encoding": schema.encoding if schema else None,
                    "message_encoding": channel.message_encoding,
                    "count": 0,
                },
            )
            t["count"] += 1
            decoded = json.loads(message.data)
            if first_pose is None and schema is not None and schema.name == "foxglove.PoseInFrame":
                p = decoded["pose"]["position"]
                first_pose = [p["x"], p["y"], p["z"], message.log_time]
    stats = summary.statistics if summary else None
    print(
        json.dumps(
            {
                "topics": topics,
                "summary_channels": len(summary.channels) if summary else None,
                "summary_message_count": stats.message_count if stats else None,
                "first_pose": first_pose,
            }
        )
    )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: mcap_summary.py FILE.mcap")
    try:
        main(sys.argv[1])
    except Exception as e:  # one line, whatever the reader's complaint
        sys.exit(f"{sys.argv[1]}: {type(e).__name__}: {e}")
