"""Reads an MCAP file with the PyPI `mcap` reader (the reference implementation) and prints, as
one JSON object, the messages and the schema of every topic. Every message is parsed as JSON.

Usage: python3 mcap_read.py FILE.mcap   (needs `pip install mcap`)
"""

import json
import sys

from mcap.reader import make_reader


def main(path):
    counts, schemas, encodings = {}, {}, {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        for schema, channel, message in reader.iter_messages(log_time_order=True):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            schemas[channel.topic] = schema.name
            encodings[channel.topic] = [channel.message_encoding, schema.encoding]
            json.loads(message.data)
    print(json.dumps({
        "counts": counts,
        "schemas": schemas,
        "encodings": encodings,
        "statistics_messages": summary.statistics.message_count if summary else None,
    }))


if __name__ == "__main__":
    main(sys.argv[1])
