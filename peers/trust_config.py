"""How a peer tests and weights its neighbours: :class:`TrustConfig` (the settings of
:class:`peers.trust.Trust`; the defaults' calibration: docs/trust-calibration.md)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TrustConfig:
    """How neighbours are tested and weighted (defaults: calibrated, docs/trust-calibration.md)."""

    enabled: bool = True
    kappa: float = 1.0
    """Weight of the cardinality term."""
    cap: float = 8.0
    """Largest per-round statistic: one scan of total disagreement (an honest peer whose
    track died a scan before the others') cannot quarantine on its own; a lie keeps it up."""
    location_only: bool = False
    """The divergence test's ``D_CS`` less the divergence of the same two densities with
    every component moved to the origin (:func:`peers.trust_checks.centred`): for
    two Gaussians that leaves half the squared Mahalanobis distance of their means in the
    sum of their covariances, whose honest mean is half the dimension whatever the
    covariances' shapes. The shape part is not evidence of a lie: two honest radars that
    see one target from different sides have differently oriented covariances (seed 001:
    1.6 on average, up to 3 under manoeuvre, above the score's drift of 2 with the rest;
    19 % of honest triples quarantined on the evaluation runs, issue 36 item 5). On for
    single-target peers (:func:`sim.run.peers.trust_config`), whose densities are one
    Gaussian each (:attr:`single_target`); not for multi-target mixtures, where the
    centred divergence also holds the profile of the weights (a tight phantom's own
    overlap) and would take a phantom's evidence away with the shapes."""
    single_target: bool = False
    """The densities are single-target summaries, a mixture over motion models of one target
    (IMM peers, seed 001 eq. 12): each is tested as the position part of its
    moment-matched Gaussian (where the target is; the covariance holds the models'
    spread). Compared model by model and in all six state variables, two honest IMMs whose
    models lag a manoeuvre differently (different model probabilities, a constant-velocity
    component tens of metres behind) failed the offset test on 16 scans in a row, and the
    divergence's honest mean, half the dimension under consistent filters, was 3 against
    the score's drift of 2."""
    empty_penalty: float = 5.0
    """Statistic added when exactly one side is empty (where cannot be compared; an honest
    peer that missed its only target publishes nothing after level-2 pruning)."""
    drift: float = 2.0
    """Per-scan allowance of the score: ``S_k = max(0, leak S_(k-1) + T_k - drift)`` (a leaky
    CUSUM: a strong lie is caught at once, a mild persistent one accumulates)."""
    leak: float = 0.8
    """Fraction of the score carried to the next scan (old evidence fades: re-admission)."""
    suspect: float = 3.5
    """Score above which a neighbour's weight is reduced: the 99th percentile of honest
    neighbours' scores on the training runs (docs/trust-calibration.md)."""
    quarantine: float = 8.6
    """Score at which its weight is 0 and it is quarantined: their 99.9th percentile."""
    readmit: int = 5
    """Scans in a row under ``suspect`` before a quarantined neighbour is trusted again."""
    majority: bool = True
    """Subtract the median test between the other inputs (own and the trusted neighbours but
    the tested one, when there are at least three): a neighbour is scored for disagreeing
    with a majority that agrees, not for a scan where everybody disagrees (a birth seen a scan
    apart, misses at Pd 0.9). The W-MSR idea (LeBlanc, Zhang, Koutsoukos & Sundaram 2013,
    "Resilient asymptotic consensus in robust networks", IEEE JSAC 31(4)) of discarding only
    values extreme against the others, as a soft score."""
    median_test: bool = True
    """With the majority term: a neighbour's test is its median test against the other inputs
    (own and the trusted neighbours but it), not the smaller of its tests against own and
    against their average. Two liars telling the same lie make the average look like them
    (each one's phantoms are in the other's reference); the median of the pair tests is
    moved by neither while the honest inputs are the majority (W-MSR's premise)."""
    repeat: bool = True
    """A neighbour whose non-empty density at a scan is, to the last bit, the one it sent at an
    earlier scan is quarantined at once (statistic ``quarantine + drift``): a filter's
    posterior changes every scan (the prediction adds the process noise ``Q`` to every
    covariance, the update takes information away), so an exact repeat is a stuck sensor or a
    replayed estimate, never noise. The same object handed in again (a stale input reused by
    the out-of-sequence policy) is not a repeat, nor is a density with no component of weight
    :attr:`repeat_weight` (the birth intensity alone is the same every scan: an honest peer
    that saw nothing publishes it again under link faults, 5 times on a training run)."""
    repeat_weight: float = 0.5
    """Smallest heaviest-component weight of a density the repeat test looks at (the
    extraction threshold: a repeated *target*)."""
    renormalise: bool = True
    """What a neighbour loses is shared over own and the trusted neighbours in proportion to
    their consensus weights (the weights renormalised over the trusted set); False: all of it
    to own (as if the edge were cut)."""
    bias: bool = True
    """The offset test: a biased sensor (every estimate a fixed distance off, its covariance
    honest) is, scan by scan, within an honest neighbour's scatter, but its offset is the same
    every scan while honest errors average out. Each target-weight component of the neighbour
    (weight :attr:`repeat_weight`) is matched to own's nearest one within :attr:`bias_gate`
    metres; the position differences ``d_i`` with summed covariances ``S_i`` of the last
    scans of each window of :attr:`bias_windows` give the information-weighted mean offset
    ``b = I^-1 y`` (``I = sum S_i^-1``, ``y = sum S_i^-1 d_i``) and its chi-square
    ``y' I^-1 y`` (2 degrees of freedom), which grows linearly with the window under a
    constant offset. Above its window's :attr:`bias_thresholds` the scan's statistic is at
    least ``quarantine + drift``."""
    bias_relative: bool = True
    """With three or more neighbours offset against own at a scan: each one's offset taken
    relative to the median of the others' (:func:`peers.trust_checks.relative_offsets`)."""
    bias_windows: tuple[int, ...] = (3, 16)
    """Scans in the offset test's windows (a short one for an offset large against the
    covariances, a long one for a small one)."""
    bias_gate: float = 60.0
    """Largest position distance (m) of a matched pair (farther: another target or a lie the
    divergence test already sees)."""
    gate_chi2: float | None = 13.82
    """Besides :attr:`bias_gate`: two target components are also one target (paired by the
    offset test, matched by the unmatched-target and withheld-target tests, corroborated by
    a repair) when their position difference is within this chi-square gate of their own
    uncertainty (:func:`peers.trust_checks.gated`: twice the pair's smaller position
    covariance). 13.82 is the 99.9 % quantile of chi-square with 2 degrees of freedom. For
    estimates hundreds of metres uncertain (the Paris radars: 9 % of honest pairs within
    60 m, 90 % within this gate) the metric gate alone counted most honest targets as
    withheld (issue 36 item 5); None: the metric gate only."""
    bias_thresholds: tuple[float, ...] = (32.0, 40.0)
    """Per window: the chi-square of its mean offset above which the neighbour is
    quarantined (above the largest honest value on the training runs, docs/trust-calibration.md)."""
    bias_cusum: bool = True
    """A sequential offset test besides the windows: per neighbour, Page's CUSUM (Page 1954,
    "Continuous inspection schemes", Biometrika 41(1/2)) of the log-likelihood ratio of a
    bias of :attr:`bias_cusum_offset` metres against none, one chart per direction of
    :attr:`bias_cusum_directions` (:func:`peers.trust_checks.offset_cusum`); above
    :attr:`bias_cusum_threshold` the scan's statistic is at least ``quarantine + drift``.
    Honest offsets are correlated over scans (lag-1 correlation 0.5-0.7 on seed 000's
    training runs), which the increments, written for independent scans, ignore: the
    threshold, not a whitening, absorbs it (set above the largest honest value on the
    training runs, docs/trust-calibration.md)."""
    bias_cusum_offset: float = 30.0
    """The alternative's offset (m): a 30 m-class biased sensor (the reference value of the
    CUSUM is half of it along each chart's direction)."""
    bias_cusum_directions: int = 8
    """Charts, one per direction ``2 pi m / directions`` (a bias between two loses at most a
    factor ``cos(pi / directions)`` of its increment)."""
    bias_cusum_threshold: float = 20.0
    """CUSUM value (nats, before correlation) at which the neighbour is quarantined: above
    the largest honest value on the training runs 9000-9001 (19.7)."""
    register: bool = True
    """A neighbour the offset test fires on is repaired instead of quarantined
    (registration; on by default, docs/trust-calibration.md says why): its offset, the
    generalised-least-squares estimate ``I^-1 y`` over the longest window of
    :attr:`bias_windows` (against own, or relative to the others' median,
    :attr:`bias_relative`), is subtracted from its position means before it is tested and
    fused, and re-estimated every scan until its CUSUM (:attr:`bias_cusum`) falls back to
    0. A biased sensor still carries its measurements; leaving it out loses them."""
    register_drift: bool = True
    """With :attr:`register`: the registered offset follows a drifting one (issue 36): it is
    fitted as ``a + b t`` over the window (:func:`peers.trust_checks.gls_trend`) and
    predicted to each scan it is subtracted at, and the offset test pairs a registered
    neighbour's components with own's around that prediction (within :attr:`bias_gate` of
    it), so a bias that outgrows the gate is still measured. False: the window's mean
    offset, last scan's, and pairs within the gate of no offset (a constant bias only)."""
    register_drift_chi2: float = 0.0
    """With :attr:`register_drift`: the chi-square of the fitted rate above which the rate
    is used (below it: the window's mean offset, as for a constant bias; 0: always)."""
    register_window: int = 32
    """With :attr:`register_drift`: scans of offsets the drift fit is over (the offset
    test's windows are :attr:`bias_windows`). The fit's offset at the window's end has
    about four times the variance of the window's mean, so a constant bias is registered
    noisier than by the mean over the same scans; a longer window takes most of that back.
    Chosen with :attr:`register_drift_chi2` on seed 000's training runs 9000-9003
    (:mod:`sim.studies.lying.drift`, the hybrid) as the pair of windows 16, 24, 32, 40, 48
    and gates 0-50 with the smallest worst ratio of the last 30 scans' fused OSPA to clean
    (13.0 m) over the *biased* lie and drifts of 1 and 2 m/scan, among those that cost
    *biased* at most 0.5 m of whole-run fused OSPA against the mean registration: 32 and 0,
    1.07 (13.8, 13.8, 13.9 m; *biased* 18.5 against 18.3 whole-run). 16 and 0: 1.19, and
    *biased* 19.2; 16 and 35: 1.21."""
    readmit_offset: bool = True
    """A quarantined neighbour is trusted again only at a scan where its residual offset
    (what is left after its registered offset, over every window of :attr:`bias_windows`)
    passes the offset test's thresholds, besides :attr:`readmit` scans under
    :attr:`suspect`: a liar whose registration runs behind its offset stays out."""
    repair: bool = True
    """A neighbour whose statistic at a scan would take its score above :attr:`repair_from`
    is offered a repaired density instead (:mod:`peers.trust_repair`; on by default,
    docs/trust-calibration.md says why): its components that neither own nor two other trusted
    neighbours (the one other, with one) show a target near (within :attr:`bias_gate`)
    dropped, its weights scaled by the median over :attr:`repair_window` scans of what own
    (or, with three or more, the others' median) weighs the same targets per unit of its
    weight, and when nothing is corroborated its offset registered
    (:attr:`repair_offset_gate`). Where the repaired density's statistic is smaller, it is
    scored and fused in the neighbour's place. An *inflated*, *phantoms* or *shifted* liar
    still carries its measurements; leaving it out loses them."""
    repair_offset_gate: float = 250.0
    """With :attr:`repair`: a neighbour none of whose components is corroborated is
    registered (:meth:`peers.trust.Trust._moved`): its offset against own, pairs up to this
    many metres apart (the largest constant offset repaired; at most :attr:`bias_gate`:
    none), subtracted over the scans it was in this case, and its covariances at least own's
    nearest component's; then repaired as any other."""
    repair_from: float = 3.5
    """The score a neighbour's statistic would take it above before it is first offered a
    repair (:attr:`suspect`'s value; kept apart so the calibration, which opens
    :attr:`suspect`, repairs as a real run does); once a repair kept a component it is
    offered one at every scan that would accumulate, for :attr:`repair_window` scans."""
    repair_window: int = 16
    """Scans of mass factors (:func:`peers.trust_repair.scan_factor`) whose median scales a
    repaired density: an inflated liar's factor is the same every scan, an honest one's
    scatters about 1 (one scan's would replace the neighbour's weights with own's)."""
    detection_probability: float | None = None
    """The smallest detection probability of this peer's and its neighbours' sensors (set from the
    scenario); None (and 1, which is taken as None: seed 001's sensors, where the defence
    refused to start before issue 36): no missed-detection explanation. Two honest densities
    that disagree completely (one side empty, or its targets far from the other's) are what a
    missed detection does to a level-2 pruned posterior (a target missed this scan falls under
    the publishing threshold) or what a target born a scan apart does; the statistic is the
    smaller of the divergence test and the evidence needed to explain the whole disagreement by
    misses, ``-log(1 - Pd)`` per target on either side (:func:`peers.trust_checks.miss_cost`:
    the log-likelihood ratio of a density that lacks a target, lying against honest)."""
    unmatched: bool = True
    """With :attr:`detection_probability`: the statistic is at least ``-log(1 - Pd)`` per
    target one side shows and the other has nothing within :attr:`bias_gate` metres of
    (:func:`peers.trust_checks.unmatched_weights`): the log-likelihood ratio of targets one
    honest peer lacks, a miss or a birth a scan apart at rate ``1 - Pd`` (phantoms are
    that every scan). The divergence alone counts an extra target next to a matched one
    for little (the overlap of the matched ones dominates)."""
    unmatched_cost: float = 2.0
    """Statistic per unit of unmatched target weight (:attr:`unmatched`)."""
    withhold: bool = True
    """With :attr:`detection_probability`: a sequential test for withheld targets (a
    neighbour that shows less than its references, *empty* at the extreme). Per neighbour,
    Page's CUSUM (Page 1954, "Continuous inspection schemes", Biometrika 41(1/2)) of the
    per-scan log-likelihood ratio of withholding against honest misses,
    :func:`peers.trust_checks.withheld_increments` (a Bernoulli miss per unit of target
    weight, Wald's SPRT increment), ``g_k = max(0, g_(k-1) + l_k)``: no drift and no leak,
    so a scan where nothing can be compared (own briefly empty too) holds it instead of
    letting it fade, and a matched target takes it back to 0 at once. Each fresh estimate
    (:attr:`same_scan`) adds one increment; late and stale ones add none. Above
    :attr:`withhold_threshold` the scan's statistic is at least ``quarantine + drift``."""
    withhold_alternative: float = 0.99
    """The alternative's rate of lacking a target (a withholding neighbour lacks nearly all;
    one matched target then costs as much as a missing one gains, ``log((1 - 0.99) / Pd)``
    against ``log(0.99 / (1 - Pd))``)."""
    withhold_cap: float = 4.47
    """Largest increment of one scan (nats): ``-log`` of the rate at which an honest
    neighbour showed no target while its references showed some (a whole loss: its
    filter dropping every track at once), 1,107 of 96,632 (peer, neighbour, scan) triples
    (1.15 %) on the training runs 9000-9001 (every graph and condition of
    :mod:`sim.studies.lying.trust_calibration`). Without it a filter that loses two targets for two
    scans
    is as much evidence as a liar's four scans of one."""
    withhold_threshold: float = 14.0
    """CUSUM value (nats) at which the neighbour is quarantined: above three scans of a whole
    loss (``3 x 4.47 = 13.4``; the largest honest value on the training runs 9000-9001 was
    13.4, circulant graph at Pd 0.9, and 13.3, seed 000 clean) and below four (17.9). It was
    10 before the hold (:attr:`withhold_hold`); its record: docs/trust-calibration.md."""
    withhold_hold: float | None = 4.47
    """CUSUM value (nats) above which the neighbour's weight is 0 for the scan (held), not
    quarantined: more than one scan's evidence (:attr:`withhold_cap`), so a single scan's
    whole loss never holds and two scans of withholding do. A held neighbour is fused again
    at the first scan its CUSUM is back under it (each scan it shows its references'
    targets takes ``log(Pd / 0.01)``, 4.6 at Pd 0.99, per unit of their weight off: one
    scan after a loss of two, two after a loss of three), with no hysteresis and no state
    change; it stays a reference. What it costs an honest neighbour: its weight while it
    shows less than its references, which is what a filter that lost its tracks should
    weigh. None: no hold (quarantine at :attr:`withhold_threshold` only)."""
    same_scan: bool = True
    """Test each neighbour estimate once, against own's density of the scan it was made
    at: an estimate used again at a later scan (its successor late or lost, predicted
    forward by the out-of-sequence policy) adds no evidence (statistic 0) and is no
    reference for the others; one that arrives after its scan is tested, at its first use,
    against own's density of its scan (kept for :attr:`keep_own` scans). Without this a
    single missed detection followed by a lost estimate counted two or three times."""
    keep_own: int = 5
    """Scans of own's round-0 densities kept for late estimates (the out-of-sequence
    window)."""
    test_once: bool = True
    """Test the neighbours in full once a scan (round 1) where that round found nothing: a
    later round whose neighbours were all tested at this scan's round 1 with full trust
    and a scan statistic of at most :attr:`drift` (or quarantined), none repaired, held or
    late, and whose densities are each within :attr:`drift` of own's by the divergence
    test against own alone (the guard: one matrix of overlaps), takes each one's round-1
    trust (:meth:`peers.trust.Trust.weigh`); any other round is tested in full. About a
    quarter of the defence's CPU at two rounds. What it gives up: a later round's lie that
    own's density alone does not show (within ``drift`` of it) is not tested against the
    others' average and median. On by default since 2026-12-05: the lying study's cells
    unchanged on seed 000 (one round) and on the 20-peer circulant graph (two rounds,
    docs/security.md); False: every round tested in full."""
    warmup: int = 0
    """Scans at the start with no test (0: a lie told from the first scan is caught at once;
    filters that start empty agree on nothing, which the cardinality term alone scores)."""

    def __post_init__(self) -> None:
        if self.detection_probability == 1.0:  # no miss explains anything: as if none given
            object.__setattr__(self, "detection_probability", None)
        if not (0 < self.leak <= 1 and 0 <= self.suspect < self.quarantine and self.cap > 0
                and self.readmit >= 1 and self.kappa >= 0 and self.warmup >= 0
                and self.drift >= 0 and self.empty_penalty >= 0 and self.keep_own >= 0
                and (self.detection_probability is None
                     or 0.0 < self.detection_probability < 1.0)
                and len(self.bias_windows) == len(self.bias_thresholds)
                and all(w >= 1 for w in self.bias_windows) and self.register_window >= 2
                and self.bias_cusum_offset > 0 and self.bias_cusum_directions >= 1
                and 0.0 < self.withhold_alternative < 1.0 and self.withhold_cap > 0
                and (self.withhold_hold is None or self.withhold_hold >= 0)):
            raise ValueError(f"invalid trust settings {self}")
        if self.single_target and (self.register or self.repair):
            raise ValueError("trust settings: single_target needs register=False and "
                             "repair=False (a summary moved or cut without its prediction "
                             "misleads the ratio rule)")
