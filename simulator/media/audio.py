"""A source video's audio, or a time range of it, carried into an output MP4 (PyAV: packets copied, or re-encoded to AAC when MP4 cannot hold the codec).

Times are seconds of video time: ``t = 0`` is the source's first video frame, so the
audio keeps its sync with the frames (``i / fps``) whatever the streams' start times.
Packets are copied without decoding when the codec fits MP4 (AAC, MP3, AC-3, E-AC-3,
ALAC, FLAC, Opus); others (Vorbis of a WebM, PCM of a MOV) are decoded and re-encoded
to AAC. A range keeps the packets that start in ``[start_s, end_s)`` and one before as the
decoder's pre-roll, at negative times that the MP4 edit list hides (packet precision,
~21 ms for AAC at 48 kHz; to the sample when re-encoding).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from fractions import Fraction

from simulator.core.errors import InputError
from simulator.core.fileio import check_input_file

__all__ = ["MP4_COPY_CODECS", "AudioSource", "audio_source"]

#: Audio codecs copied into MP4 as they are (packets, no decoding).
MP4_COPY_CODECS = ("aac", "mp3", "ac3", "eac3", "alac", "flac", "opus")


@dataclass(frozen=True)
class AudioSource:
    """The audio stream of ``path`` to carry into outputs, limited to ``[start_s, end_s)``.

    codec : the stream's codec name; copy : True when packets are copied as they are
    (codec in :data:`MP4_COPY_CODECS`), False when re-encoded to AAC
    start_s, end_s : seconds of video time (None: from the start / to the end)
    """

    path: str
    codec: str
    copy: bool
    start_s: float = 0.0
    end_s: float | None = None

    def add_to(self, container):
        """Add the output audio stream to ``container`` (an MP4 open for writing, before its
        first packet); returns a :class:`_AudioMuxer` whose ``mux_all()`` writes it."""
        return _AudioMuxer(self, container)


def audio_source(
    path: str | os.PathLike, start_s: float | None = None, end_s: float | None = None
) -> AudioSource | None:
    """The first audio stream of ``path`` as an :class:`AudioSource`, None if it has none.

    InputError naming the file when it cannot be opened."""
    import av

    p = check_input_file(path, "video")
    try:
        with av.open(str(p)) as c:
            if not c.streams.audio:
                return None
            s = c.streams.audio[0]
            name = s.codec_context.name
    except av.error.FFmpegError as e:
        raise InputError(f"{p}: not a readable video ({e.strerror or type(e).__name__})") from None
    return AudioSource(
        str(p),
        name,
        name in MP4_COPY_CODECS,
        float(start_s or 0.0),
        None if end_s is None else float(end_s),
    )


def _video_start_s(container) -> float:
    """Start time (seconds) of the container's first video stream: video time 0."""
    if not container.streams.video:
        return 0.0
    v = container.streams.video[0]
    if v.start_time is None or v.time_base is None:
        return 0.0
    return float(v.start_time * v.time_base)


class _AudioMuxer:
    """Writes one :class:`AudioSource` into an output container (see :meth:`mux_all`)."""

    def __init__(self, src: AudioSource, out_container):
        import av

        self.src = src
        self.out = out_container
        self._in = av.open(src.path)
        try:
            self._ins = self._in.streams.audio[0]
            if src.copy:
                self.stream = out_container.add_stream_from_template(self._ins)
            else:
                rate = self._ins.codec_context.sample_rate or 48000
                self.stream = out_container.add_stream("aac", rate=rate)
                self.stream.format = "fltp"  # FFmpeg's AAC encoder takes planar float
                layout = self._ins.codec_context.layout
                # by channel count: a layout of unspecified order ("1 channels") is refused
                mono = layout is not None and layout.nb_channels == 1
                self.stream.layout = "mono" if mono else "stereo"
        except av.error.FFmpegError as e:
            self._in.close()
            raise InputError(
                f"{src.path}: its {src.codec} audio cannot go into an MP4 "
                f"({e.strerror or type(e).__name__}); --no-audio renders without it"
            ) from None
        except BaseException:
            self._in.close()
            raise
        self.n_packets = 0

    def mux_all(self) -> int:
        """Write the range's audio into the output (call once, before or after the video
        packets: the muxer interleaves); returns the number of packets written."""
        import av

        try:
            return self._copy() if self.src.copy else self._transcode()
        except av.error.FFmpegError as e:
            raise InputError(
                f"{self.src.path}: cannot carry its {self.src.codec} audio into the output "
                f"({e.strerror or type(e).__name__}); --no-audio renders without it"
            ) from None
        finally:
            self._in.close()

    def _bounds(self) -> tuple[float, float]:
        t0 = _video_start_s(self._in) + self.src.start_s
        t1 = math.inf if self.src.end_s is None else _video_start_s(self._in) + self.src.end_s
        return t0, t1

    def _copy(self) -> int:
        ins, tb = self._ins, self._ins.time_base
        t0, t1 = self._bounds()
        shift = round(Fraction(t0).limit_denominator(10**9) / tb)
        eps = 1e-6
        for pkt in self._in.demux(ins):
            if pkt.dts is None or pkt.size == 0:
                continue
            pts = pkt.pts if pkt.pts is not None else pkt.dts
            t = float(pts * tb)
            d = float((pkt.duration or 0) * tb)
            # Packets overlapping the range, plus one before it as the decoder's pre-roll
            # (AAC priming, MDCT overlap): at negative times, the MP4 edit list skips them.
            if t + 2 * d <= t0 + eps or t >= t1 - eps:
                continue
            pkt.pts = pts - shift
            pkt.dts = pkt.dts - shift
            pkt.stream = self.stream
            self.out.mux(pkt)
            self.n_packets += 1
        return self.n_packets

    def _transcode(self) -> int:
        import av

        t0, t1 = self._bounds()
        rate = self.stream.codec_context.sample_rate
        resampler = av.AudioResampler(
            format=self.stream.codec_context.format.name,
            layout=self.stream.codec_context.layout.name,
            rate=rate,
        )
        fifo = av.AudioFifo()
        frame_size = self.stream.codec_context.frame_size or 1024
        n_out = 0  # samples written

        def encode(frame):
            nonlocal n_out
            if frame is not None:
                frame.pts = n_out
                frame.time_base = Fraction(1, rate)
                n_out += frame.samples
            for pkt in self.stream.encode(frame):
                self.out.mux(pkt)
                self.n_packets += 1

        for frame in self._in.decode(self._ins):
            if frame.pts is None:
                continue
            ft0 = float(frame.pts * frame.time_base)
            ft1 = ft0 + frame.samples / frame.sample_rate
            if ft1 <= t0 or ft0 >= t1:
                continue
            for rf in resampler.resample(frame):
                # Trim to [t0, t1) to the sample (frames straddling the bounds).
                a = max(0, round((t0 - ft0) * rate))
                b = rf.samples if ft1 <= t1 else max(0, round((t1 - ft0) * rate))
                if b <= a:
                    continue
                if (a, b) != (0, rf.samples):
                    arr = (
                        rf.to_ndarray()[..., a:b]
                        if rf.format.is_planar
                        else rf.to_ndarray()[
                            :, a * len(rf.layout.channels) : b * len(rf.layout.channels)
                        ]
                    )
                    nf = av.AudioFrame.from_ndarray(
                        arr, format=rf.format.name, layout=rf.layout.name
                    )
                    nf.sample_rate = rate
                    rf = nf
                rf.pts = None
                fifo.write(rf)
                while fifo.samples >= frame_size:
                    encode(fifo.read(frame_size))
        if fifo.samples:
            encode(fifo.read())
        encode(None)
        return self.n_packets
