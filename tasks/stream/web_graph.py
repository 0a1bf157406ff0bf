"""Audio in, pose out, one graph: the streaming dancer's step with its music front end, for ONNX.

:class:`MusicFrontEnd` computes the 34 causal features of :mod:`~skeleton_mamba.tasks.stream.features` from
one hop of raw audio at :data:`~.features.SR` and a small audio state, in torch ops that export to ONNX:
the window is the state's ``N_FFT - HOP`` samples followed by the hop (zeros before the music), its real DFT
(``torch.fft.rfft``: the ONNX ``DFT`` op) of the Hann-windowed frame, the power spectrum, the mel and chroma
filterbanks and the window taken from the same librosa calls as :class:`~.features.CausalMusicFeatures`
(constant matrices), ``power_to_db`` (ref 1, amin 1e-10, no top_db), the MFCCs as the matrix of
``librosa.feature.mfcc`` (linear in the log-mel spectrum: its orthonormal DCT-II, 20 rows), the onset flux
against the previous frame's log-mel spectrum (carried as state; 0 at the first frame), chroma normalised
by its per-frame maximum (left as is below the smallest float, as ``librosa.util.normalize``) and the log
RMS of the unwindowed frame. Float32 throughout (the Python extractor computes in float64).

:class:`WebStepGraph` joins it to the dancer's step (:class:`~skeleton_mamba.tasks.training.onnx_export.
DancerStepGraph`, the music standardisation and the output low-pass inside) and to forward kinematics, so a
browser feeds 512 samples and gets the pose and the joints to draw::

    forward(audio (1, 512), audio_state (1, 1536), mel_state (1, 128), started (), prev (1, 24, 12),
            [smoothing (stages, 1, 24, 12)], conv_0, ssm_0, ...)
      -> (pose (1, 24, 12), joints (1, 24, 3), features (1, 34), next_audio_state, next_mel_state,
          [next_smoothing], next_conv_0, next_ssm_0, ...)

``started`` is 0 at a stream's first frame and 1 after (the onset and the low-pass read it); zeros are
every state of a new stream; ``prev`` is the previous frame's ``pose`` (zeros first). The joints are those
of :func:`~skeleton_mamba.tasks.stream.model.tokens_to_motion`: each predicted 3x3 block projected to its
nearest rotation (by SVD there; here :func:`nearest_rotation_graph`, from the polar factor, as ONNX has no
SVD), then the SMPL forward kinematics.
"""

from __future__ import annotations

import numpy as np
import onnxruntime
import torch
from torch import nn

from skeleton_mamba.errors import InputError
from skeleton_mamba.tasks.motion.body.smpl import smpl_forward_kinematics
from skeleton_mamba.tasks.motion.music.jit_lock import librosa_calls
from skeleton_mamba.tasks.stream.features import HOP, N_FFT, N_MELS, NUM_FEATURES, SR, CausalMusicFeatures
from skeleton_mamba.tasks.stream.model import POSE_CHANNELS, StreamDancer, tokens_to_features
from skeleton_mamba.tasks.stream.onnx_graphs import DancerStepGraph
from skeleton_mamba.tasks.training.onnx_graphs import ExportSpec, network_ready, state_names, zero_states

__all__ = [
    "AUDIO_STATE",
    "NUM_MFCC",
    "POLAR_ITERATIONS",
    "MusicFrontEnd",
    "WebStepGraph",
    "SQUARINGS",
    "check_web_dancer",
    "nearest_rotation_graph",
    "polar_rotation",
    "run_web_graph",
    "web_step_spec",
    "web_zero_inputs",
]

AUDIO_STATE = N_FFT - HOP  # samples of the window before the new hop
NUM_MFCC = 20
AMIN = 1e-10  # librosa.power_to_db's floor
RMS_EPS = 1e-5  # features.py: log(rms + 1e-5)
POLAR_ITERATIONS = 12  # scaled Newton converges in well under 10 for any non-singular 3x3 block
SQUARINGS = 12  # the adjugate's power 4096: separates singular values 0.5 % apart to float32 precision


class MusicFrontEnd(nn.Module):
    """One hop of audio (B, HOP) at SR and the audio state -> the 34 causal features (module docstring).

    forward(audio, audio_state (B, N_FFT - HOP), mel_state (B, 128), started ()) -> (features (B, 34),
    next_audio_state, next_mel_state).
    """

    def __init__(self) -> None:
        super().__init__()
        reference = CausalMusicFeatures(SR)  # the window and the filterbanks of the Python extractor
        with librosa_calls() as librosa:
            mfcc = librosa.feature.mfcc(S=np.eye(N_MELS), n_mfcc=NUM_MFCC)  # (20, 128): mfcc = M @ logmel
        self.register_buffer("hann", torch.tensor(reference.window, dtype=torch.float32))
        self.register_buffer("mel_basis", torch.tensor(reference.mel.T, dtype=torch.float32))
        self.register_buffer("chroma_basis", torch.tensor(reference.chroma.T, dtype=torch.float32))
        self.register_buffer("mfcc_basis", torch.tensor(mfcc.T, dtype=torch.float32))

    def forward(
        self, audio: torch.Tensor, audio_state: torch.Tensor, mel_state: torch.Tensor, started: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        frame = torch.cat([audio_state, audio], dim=-1)  # (B, N_FFT), ends at the hop's last sample
        spectrum = torch.fft.rfft(frame * self.hann)
        power = spectrum.real.square() + spectrum.imag.square()  # (B, 1025)
        logmel = 10.0 * torch.log10(torch.clamp(power @ self.mel_basis, min=AMIN))  # (B, 128)
        previous = started * mel_state + (1 - started) * logmel  # the first frame's flux is 0
        onset = torch.relu(logmel - previous).mean(dim=-1, keepdim=True)
        mfcc = logmel @ self.mfcc_basis
        chroma = power @ self.chroma_basis
        peak = chroma.amax(dim=-1, keepdim=True)
        chroma = chroma / torch.where(peak < torch.finfo(torch.float32).tiny, torch.ones_like(peak), peak)
        rms = torch.log(torch.sqrt(frame.square().mean(dim=-1, keepdim=True)) + RMS_EPS)
        features = torch.cat([onset, mfcc, chroma, rms], dim=-1)
        return features, frame[:, HOP:], logmel


def _cofactor(m: torch.Tensor) -> torch.Tensor:
    """The cofactor matrix of (..., 3, 3) blocks: rows b x c, c x a, a x b of rows a, b, c (= det * M^-T)."""
    a, b, c = m[..., 0, :], m[..., 1, :], m[..., 2, :]
    return torch.stack([torch.linalg.cross(b, c), torch.linalg.cross(c, a), torch.linalg.cross(a, b)], dim=-2)


def _det(m: torch.Tensor, cof: torch.Tensor) -> torch.Tensor:
    return (m[..., 0, :] * cof[..., 0, :]).sum(dim=-1)[..., None, None]


def polar_rotation(m: torch.Tensor, iterations: int = POLAR_ITERATIONS) -> torch.Tensor:
    """The orthogonal polar factor ``U V^T`` of (..., 3, 3) blocks ``U S V^T`` by scaled Newton iteration
    ``X <- (g X + X^-T / g) / 2``, ``g = sqrt(|X^-1|_F / |X|_F)`` (Higham 1986); elementwise ops only."""
    x = m
    for _ in range(iterations):
        cof = _cofactor(x)
        det = _det(x, cof)
        inv_t = cof / torch.where(det.abs() < 1e-20, torch.full_like(det, 1e-20), det)
        norm = x.square().sum(dim=(-2, -1), keepdim=True).sqrt()
        inv_norm = inv_t.square().sum(dim=(-2, -1), keepdim=True).sqrt()
        gamma = (inv_norm / norm).sqrt()
        x = 0.5 * (gamma * x + inv_t / gamma)
    return x


def nearest_rotation_graph(m: torch.Tensor, squarings: int = SQUARINGS) -> torch.Tensor:
    """The rotation nearest each (..., 3, 3) block, ``U diag(1, 1, det(U V^T)) V^T`` as
    :func:`~skeleton_mamba.tasks.motion.formats.fact_features.nearest_rotation` takes it by SVD, in ops ONNX
    has.

    The polar factor ``Q = U V^T`` (:func:`polar_rotation`) where ``det M > 0``; else ``Q (I - 2 v v^T)``
    with ``v`` the right singular vector of the smallest singular value: the dominant eigenvector of the
    adjugate of ``S = Q^T M = V diag(s) V^T`` (eigenvalues ``s1 s2 >= s1 s3 >= s2 s3``), taken as the
    largest column of its ``2^squarings``-th power (repeated squaring, normalised each time)."""
    q = polar_rotation(m)
    s = q.mT @ m
    s = 0.5 * (s + s.mT)
    power = _cofactor(s).mT  # the adjugate
    for _ in range(squarings):
        power = power / power.square().sum(dim=(-2, -1), keepdim=True).sqrt().clamp_min(1e-30)
        power = power @ power
    lengths = power.square().sum(dim=-2, keepdim=True)  # (..., 1, 3): squared column norms
    pick = (lengths == lengths.amax(dim=-1, keepdim=True)).to(power.dtype)
    v = (power * pick).sum(dim=-1, keepdim=True)  # the largest column (ties: their sum, same direction)
    v = v / v.square().sum(dim=-2, keepdim=True).sqrt().clamp_min(1e-30)
    flipped = q - 2.0 * (q @ v) @ v.mT
    return torch.where(_det(m, _cofactor(m)) < 0, flipped, q)


def check_web_dancer(dancer: StreamDancer, source: str) -> None:
    """Refuse a dancer the web graph cannot feed: one trained with the beat phase reads more than the
    :data:`~.features.NUM_FEATURES` music features the graph computes (an :class:`InputError` naming
    ``source``, e.g. ``--ckpt PATH``)."""
    if dancer.music_dim != NUM_FEATURES:
        raise InputError(
            f"{source}: this dancer reads {dancer.music_dim} music features (trained with the beat phase); "
            f"the page computes the {NUM_FEATURES} without it: train with --data.init_args.beat_phase false "
            "for the browser"
        )


class WebStepGraph(nn.Module):
    """:class:`MusicFrontEnd`, then the dancer's step, then the joints: one graph (module docstring)."""

    def __init__(self, dancer: StreamDancer):
        super().__init__()
        check_web_dancer(dancer, "the dancer")
        self.front_end = MusicFrontEnd()
        self.step = DancerStepGraph(dancer)
        self.smoothing = dancer.smoothing.enabled

    def forward(
        self,
        audio: torch.Tensor,
        audio_state: torch.Tensor,
        mel_state: torch.Tensor,
        started: torch.Tensor,
        prev: torch.Tensor,
        *states: torch.Tensor,
    ) -> tuple[torch.Tensor, ...]:
        features, next_audio, next_mel = self.front_end(audio, audio_state, mel_state, started)
        extra = (started,) if self.smoothing else ()
        pose, *next_states = self.step(prev, features, *extra, *states)
        flat = tokens_to_features(pose)  # (B, 219): root (mean of the joints' copies) | 24 rotations
        rotations = nearest_rotation_graph(flat[:, 3:].reshape(-1, 24, 3, 3))
        joints = smpl_forward_kinematics(rotations, flat[:, :3])
        return (pose, joints, features, next_audio, next_mel, *next_states)


def web_zero_inputs(dancer: StreamDancer) -> dict[str, torch.Tensor]:
    """The inputs of a new stream's first frame but the audio: every state zero, ``started`` 0."""
    inputs = {
        "audio_state": torch.zeros(1, AUDIO_STATE),
        "mel_state": torch.zeros(1, N_MELS),
        "started": torch.zeros(()),
        "prev": torch.zeros(1, 24, POSE_CHANNELS),
    }
    if dancer.smoothing.enabled:
        inputs["smoothing"] = torch.zeros(dancer.smoothing.stages, 1, 24, POSE_CHANNELS)
    states = zero_states(dancer.backbone, 1)
    inputs.update(zip(state_names(len(states)), states))
    return inputs


def web_step_spec(dancer: StreamDancer) -> ExportSpec:
    """The :class:`WebStepGraph` of ``dancer`` with example inputs (one stream, static shapes).

    The example is a started stream with random states, so that no branch is traced away."""
    network_ready(dancer)
    zeros = web_zero_inputs(dancer)
    names = list(zeros)
    examples = [torch.randn_like(t) for t in zeros.values()]
    examples[names.index("started")] = torch.ones(())
    state_names = names[names.index("prev") + 1 :]
    outputs = ["pose", "joints", "features", "next_audio_state", "next_mel_state"]
    outputs += [f"next_{n}" for n in state_names]
    return ExportSpec(
        WebStepGraph(dancer), (torch.randn(1, HOP) * 0.1, *examples), ["audio", *names], outputs,
        varargs_from=5,
    )  # fmt: skip


def run_web_graph(
    path: str, dancer: StreamDancer, audio: np.ndarray, beside: str | None = None
) -> dict[str, np.ndarray]:
    """Step the web graph at ``path`` with onnxruntime over mono ``audio`` at SR, as the page does:
    one call per complete hop, each output state fed back. Returns (T, ...) ``pose``, ``joints``,
    ``features``; with ``beside`` (another web graph of ``dancer``, e.g. quantized), also that graph's
    ``beside_joints`` (T, 24, 3), each frame stepped from ``path``'s state of that frame (one step apart)."""
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    other = (
        None
        if beside is None
        else onnxruntime.InferenceSession(str(beside), providers=["CPUExecutionProvider"])
    )
    feeds = {k: v.numpy() for k, v in web_zero_inputs(dancer).items()}
    names = [o.name for o in session.get_outputs()]
    out: dict[str, list[np.ndarray]] = {"pose": [], "joints": [], "features": []}
    if other is not None:
        out["beside_joints"] = []
    audio = np.asarray(audio, dtype=np.float32).reshape(-1)
    for t in range(len(audio) // HOP):
        feeds["audio"] = audio[None, t * HOP : (t + 1) * HOP]
        result = dict(zip(names, session.run(None, feeds)))
        if other is not None:
            result["beside_joints"] = other.run(["joints"], feeds)[0]
        for key in out:
            out[key].append(result[key][0])
        feeds["prev"], feeds["started"] = result["pose"], np.ones((), np.float32)
        for name in feeds:
            if f"next_{name}" in result:
                feeds[name] = result[f"next_{name}"]
    return {k: np.stack(v) if v else np.zeros((0,)) for k, v in out.items()}
