# SPDX-License-Identifier: Apache-2.0
r"""Live motion sources and the live run: ``qpretarget stream`` / ``qpretarget live``.

* :mod:`.base` — the :class:`Source` interface: :class:`Frame`\\ s with a sample number, a receive
  time and named joint positions and orientations;
* :mod:`.registry` — ``--source NAME[:ARG]`` -> a source (:data:`SOURCES`, :func:`open_source`);
* :mod:`.mvn` — Xsens MVN ``MXTP02`` datagrams (encoder, decoder, segment table);
* :mod:`.xsens` — the MVN network streamer over UDP; :mod:`.file` — a mocap file in real time;
* :mod:`.session` — :class:`LiveSession`: gaps, holds, resumes, latency and deadlines;
* :mod:`.publish` — commands to a callback, UDP (binary or JSON) or the browser viewer.

docs/live.md has the protocol, the layouts and the measured latencies.
"""

from .base import Frame, Source, SourceError
from .publish import LiveCommand, UdpPublisher, decode_command, encode_command
from .registry import SOURCES, load_sources, open_source
from .session import LiveSession, latency_stats

__all__ = [
    "SOURCES",
    "Frame",
    "LiveCommand",
    "LiveSession",
    "Source",
    "SourceError",
    "UdpPublisher",
    "decode_command",
    "encode_command",
    "latency_stats",
    "load_sources",
    "open_source",
]
