"""Training recipes. `paper` is the authors' recipe (reference notes section 3);
`cpu` is designed for 2 CPU cores (see BENCHMARKS.md for how it was chosen)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace


@dataclass(frozen=True)
class TrainConfig:
    preset: str
    steps: int
    batch: int = 64
    crop: int | None = None  # frames per training example; None = the whole clip
    # a clip of at most this many frames trains whole even where `crop` is set (train.data.choose_crop)
    whole_clip_frames: int | None = None
    # crop starts may fall this share of the crop off either end of the clip, then are clamped in
    # (train.data.crop_starts): 0 = uniform starts, under which the clip's first and last frames are
    # almost never trained on
    crop_edges: float = 0.0
    rescale: tuple[float, float] | None = (0.75, 1.25)  # random time-rescale range per iteration
    lr: float = 1e-4
    lr_schedule: str = "exponential"  # "exponential" (gamma per step) | "linear-tail" (linear decay to 0 over the last `tail` share)
    lr_gamma: float = 0.99998
    lr_tail: float = 0.3
    weight_decay: float = 0.0
    ema: float | None = None
    bf16: bool = False  # autocast where the device supports it
    width: int = 256
    norm: str = "group"
    dropout: float = 0.5
    fps: float = 30.0
    checkpoint_every: int = 200
    log_every: int = 10
    # The watch (watch.py): score the EMA weights every `check_every` steps (None: never),
    # keep the best-balanced checkpoint, stop `patience` checks after the best once in band.
    check_every: int | None = None
    patience: int = 3
    early_stop: bool = True
    fallback_norm: str | None = None  # a run that stops COPYING spends its remaining steps on this norm
    # a run whose fallback norm stage stops COPYING too spends what is left on its own norm with the foot-contact
    # loss ("clip" target) at this weight (trainer._fallback_stages); 0: not tried
    fallback_foot_loss: float = 0.0
    # a run that stops STALLED (losing coverage short of the band) spends what is left with crop starts reaching
    # this far off the clip's ends and the foot-contact loss ("clip") at `stalled_foot_loss` (trainer._fallback_stages)
    stalled_crop_edges: float = 0.0
    stalled_foot_loss: float = 0.0
    # checks sample as `sample` will: the foot cleanup on, shaking samples smoothed where calibration would
    # smooth them (eval.balance.ClipScorer.check_as_sampled); False: raw samples, no cleanup
    check_cleanup: bool = False
    loss_weighting: str = "uniform"  # over t: "uniform" (the paper) | "min-snr" (train.diffusion.min_snr_weighting)
    foot_loss: float = 0.0  # weight of the foot-contact loss (train/foot_loss.py; 0 = the paper's loss alone)
    # "still": the clip's planted joints held still (MDM's); "clip": every contact joint's velocity
    # matched to the clip's, weighted by the noise level's share of signal
    foot_loss_target: str = "still"
    velocity_unit: str = "frame"  # the root velocity channels in metres per "frame" (paper) or "second" (runtime.features.model_scale)
    # the trajectory joint seen in the "world" (paper) or from its "heading" (runtime.heading);
    # "auto": the heading for a clip that turns steadily, the world otherwise (trainer.choose_root_frame)
    root_frame: str = "world"

    def to_dict(self) -> dict:
        data = asdict(self)
        data["rescale"] = list(self.rescale) if self.rescale else None
        return data

    @classmethod
    def from_dict(cls, data: dict) -> "TrainConfig":
        known = {f.name for f in fields(cls)}
        values = {k: v for k, v in data.items() if k in known}
        if values.get("rescale") is not None:
            values["rescale"] = tuple(values["rescale"])
        return cls(**values)

    def with_overrides(self, **changes) -> "TrainConfig":
        return replace(self, **{k: v for k, v in changes.items() if v is not None})


PRESETS = {
    "paper": TrainConfig(preset="paper", steps=60_000),
    "cpu": TrainConfig(
        preset="cpu",
        steps=2_800,
        crop=64,
        whole_clip_frames=96,
        rescale=None,
        lr=2e-4,
        lr_schedule="linear-tail",
        ema=0.999,
        bf16=True,
        check_every=200,
        fallback_norm="frame",
        fallback_foot_loss=0.001,
        stalled_crop_edges=0.25,
        stalled_foot_loss=0.0003,
        root_frame="auto",
        check_cleanup=True,
    ),
}


def preset(name: str) -> TrainConfig:
    from ..runtime.errors import SinMDMError

    if name not in PRESETS:
        raise SinMDMError(f"unknown preset '{name}': choose one of {', '.join(PRESETS)}")
    return PRESETS[name]
