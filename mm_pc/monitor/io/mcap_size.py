"""How big a recording's file is so far, before the mcap writer puts it on disk (no Qt).

The mcap writer keeps the open chunk (up to 1 MiB of records) in memory and writes it
compressed (zstd) when it is full, so the file on disk grows in steps of about 0.2 MB
and stays at 0 kB for the first minutes at 15 Hz. :class:`SizeTracker` counts the bytes
handed to the writer instead (each record's size from the MCAP spec) and tells what the
file would measure if it were closed now (bytes):

* what is on disk (the file position);
* the open chunk: its records times the compression ratio -- the last written chunk's,
  or before the first one, that of zstd on a sample of the data -- plus its message
  index and chunk header;
* the summary :meth:`finish` writes: the schemas and channels again, one index per
  chunk, the statistics, the footer.

The Metadata records written at close (~2 kB, the rosbag2 one grows with the topics)
are added by the recorder (:func:`metadata_bytes`).
"""

from __future__ import annotations

import struct

__all__ = ["SizeTracker", "channel_bytes", "message_bytes", "metadata_bytes", "schema_bytes"]

#: bytes of data compressed to find the ratio before the first chunk is written
SAMPLE_BYTES = 256 * 1024
#: MCAP records' fixed parts (opcode, length and fixed fields, bytes): a Chunk record
#: around its compressed records; a MessageIndex per channel (and 16 per message); a
#: ChunkIndex in the summary (and 10 per channel); the Statistics (and 10 per channel);
#: the summary's tail (SummaryOffsets, DataEnd, Footer, magic)
CHUNK_HEAD = 53
INDEX_HEAD, INDEX_ENTRY = 15, 16
CHUNK_INDEX, CHUNK_INDEX_PER_CHANNEL = 81, 10
STATISTICS, STATISTICS_PER_CHANNEL = 59, 10
SUMMARY_TAIL = 6 * 26 + 13 + 29 + 8


_MESSAGE = struct.Struct("<BQHIQQ")  # opcode, length, channel, sequence, log and publish time


def _string(text: str) -> int:
    return 4 + len(text.encode())


def message_bytes(data_len: int) -> int:
    """A Message record around ``data_len`` bytes of data."""
    return 31 + data_len


def schema_bytes(name: str, encoding: str, data_len: int) -> int:
    """A Schema record."""
    return 11 + _string(name) + _string(encoding) + 4 + data_len


def channel_bytes(topic: str, encoding: str, metadata: dict[str, str]) -> int:
    """A Channel record."""
    return 13 + _string(topic) + _string(encoding) + _map(metadata)


def _map(fields: dict[str, str]) -> int:
    return 4 + sum(_string(k) + _string(v) for k, v in fields.items())


def metadata_bytes(records: list[tuple[str, dict[str, str]]]) -> int:
    """Metadata records (name, fields) and their MetadataIndex records in the summary."""
    return sum(9 + _string(name) + _map(fields) + 29 + _string(name) for name, fields in records)


class SizeTracker:
    """Counts what is handed to an mcap ``Writer`` writing to ``stream`` (zstd chunks).

    Call :meth:`schema` / :meth:`channel` after registering one, :meth:`message` after
    each ``add_message`` (it notices a chunk written from the stream's position);
    :meth:`estimate` is the file's size if it were closed now. Not thread-safe: the
    recorder calls it under its lock.
    """

    def __init__(self, stream) -> None:
        self._stream = stream
        self._disk = stream.tell()  # bytes written (or buffered) to the file so far
        self._open = 0  # uncompressed bytes of the open chunk's records
        self._open_messages = 0
        self._open_channels: set[int] = set()
        self._ratio: float | None = None  # compressed / uncompressed, last chunk
        self._sample = bytearray()
        self._sample_ratio = (0, 1.0)  # (sample length, its ratio)
        self._summary = SUMMARY_TAIL + STATISTICS
        self._chunks = 0
        self._chunk_index = 0  # ChunkIndex records so far (bytes)

    def schema(self, name: str, encoding: str, data: bytes) -> None:
        size = schema_bytes(name, encoding, len(data))
        self._sample += f"{name}{encoding}".encode() + data
        self._open += size
        self._summary += size

    def channel(self, topic: str, encoding: str, metadata: dict[str, str]) -> None:
        size = channel_bytes(topic, encoding, metadata)
        self._sample += "".join([topic, encoding, *metadata, *metadata.values()]).encode()
        self._open += size
        self._summary += size + STATISTICS_PER_CHANNEL

    def message(self, channel: int, log_time: int, data: bytes, publish_time: int,
                sequence: int) -> None:  # fmt: skip
        self._open += message_bytes(len(data))
        self._open_messages += 1
        self._open_channels.add(channel)
        if len(self._sample) < SAMPLE_BYTES:  # the record as the chunk holds it
            self._sample += _MESSAGE.pack(
                5, 30 + len(data), channel, sequence, log_time, publish_time
            )
            self._sample += data
        position = self._stream.tell()
        if position != self._disk:  # the writer wrote the chunk, this message included
            overhead = CHUNK_HEAD + self._index_bytes()
            compressed = max(position - self._disk - overhead, 0)
            self._ratio = compressed / self._open if self._open else None
            self._chunks += 1
            self._chunk_index += CHUNK_INDEX + CHUNK_INDEX_PER_CHANNEL * len(self._open_channels)
            self._disk = position
            self._open = self._open_messages = 0
            self._open_channels.clear()

    def _index_bytes(self) -> int:
        return INDEX_HEAD * len(self._open_channels) + INDEX_ENTRY * self._open_messages

    def _compression(self) -> float:
        if self._ratio is not None:
            return self._ratio
        n, ratio = self._sample_ratio
        if len(self._sample) > n:  # grown: compress it again (<= 256 kB, ~1 ms)
            import zstandard

            ratio = len(zstandard.compress(bytes(self._sample))) / len(self._sample)
            self._sample_ratio = (len(self._sample), ratio)
        return ratio

    def estimate(self) -> int:
        """The file's size (bytes) if the writer finished now (Metadata records aside)."""
        size = self._disk + self._summary + self._chunk_index
        if self._open_messages:
            size += round(self._open * self._compression()) + CHUNK_HEAD + self._index_bytes()
            size += CHUNK_INDEX + CHUNK_INDEX_PER_CHANNEL * len(self._open_channels)
        return size
