"""The sections of a scenario about the peers: how they fuse (``[fusion]``), their network
(``[network]``) and the settings of particular peer kinds (``[extended]``, ``[clustering]``,
``[lmb]``; ``[pda]`` is :mod:`sim.scenario.pda`); re-exported by :mod:`sim.scenario.model`.
Each option is declared once in its field (:func:`sim.scenario.options.option`)."""

from __future__ import annotations

from dataclasses import dataclass

from sensornet.sim.bounds import MAX_ROUNDS
from sensornet.sim.choices import FUSION_RULES, OMEGA_RULES, OOS_POLICIES
from sensornet.sim.kinds import names as kind_names
from sensornet.sim.scenario.common import (
    ASSUMED_SCANS,
    DISTANCE_UNITS,
    FLOOD_ESTIMATORS,
    K_RULES,
    PARTITIONS,
    TOPOLOGIES,
)
from sensornet.sim.scenario.options import (
    NONNEGATIVE,
    POSITIVE,
    PROBABILITY,
    Bound,
    at_least,
    option,
)
from sensornet.tracking.gci_product import CARDINALITY_RULES
from sensornet.tracking.gmphd import EXTRACTION_RULES


@dataclass(frozen=True)
class FusionSpec:
    """How local estimates are fused (§3, §4 level 2)."""

    rule: str = option("hybrid", doc="`\"hybrid\"` (AA target weights, GCI locations: "
                                     "`tracking.fusion_rules.hybrid_fuse`), `\"gci\"`, `\"aa\"` "
                                     "(arithmetic average), `\"ratio\"` (the particle rule, IMM "
                                     "peers) or `\"none\"` (local filters only); each peer kind "
                                     "takes some.", choices=FUSION_RULES)
    fusing_omega: str = option("uniform", doc="The offline experiment's fusion weights at the "
                                              "fusing sensor: `\"uniform\"`, `\"metropolis\"` "
                                              "(of the star it forms with the others) or "
                                              "optimised `\"det\"` / `\"chernoff\"` (the peers' "
                                              "are `network.omega`).",
                               choices=OMEGA_RULES, was="omega")
    level2_pruning: bool = option(True, doc="Publish only components heavier than "
                                            "`level2_threshold`.")
    level2_threshold: float = option(0.5, doc="Level-2 pruning threshold.", check=NONNEGATIVE)
    fusing_sensor: str = option("", doc="The sensor that fuses in the offline experiment (seed "
                                        "000: `\"s2\"`), and the hub of a `\"star\"` network.",
                                custom="the first sensor")
    cardinality: str = option("separate", doc="GCI target number: `\"emd\"` (exact Poisson "
                                              "EMD, Uney 2013) or `\"separate\"` (location "
                                              "densities and cardinalities fused apart, "
                                              "Battistelli 2013).", choices=CARDINALITY_RULES)
    support: int = option(-2, doc="Report a fused track only if this many of the fusion's "
                                  "inputs hold a component within the hybrid gate of it, or "
                                  "it was extracted in `support_scans` consecutive scans "
                                  "(`tracking.support`; extraction only, the fused density is "
                                  "unchanged); 0: every extracted track; -1: more than half "
                                  "of the round's inputs, at least 2 (`tracking.support."
                                  "MAJORITY`); -2 (auto): -1 for GM-PHD peers whose births "
                                  "are alike at every peer (fixed birth points, `network."
                                  "birth_ids` `\"shared\"`), else 2 (`sim.run.peers."
                                  "support_inputs`). Labelled (GM-PHD, LMB) peers only. "
                                  "Issue 33: on training runs 2 removes the GM-PHD's one-scan "
                                  "false fused tracks and the majority most of the rest "
                                  "(circ20 Pd 0.99 11.8 -> 9.4 m); the LMB gains nothing "
                                  "from the majority (docs/labelled-tracking.md, \"Fused "
                                  "false tracks need a majority of the inputs\").",
                          check=at_least(-2))
    support_scans: int = option(2, doc="With `support`: scans a fused track held by fewer "
                                       "inputs must be extracted in a row before it is "
                                       "reported.", unit="scans", check=at_least(1))
    existence_prior: float = option(-1.0, doc="Extraction of fused tracks (labelled peers): "
                                              "a track at most `existence_young` scans old "
                                              "that two inputs or more hold weighs at least "
                                              "their existences pooled as independent "
                                              "evidence with this prior existence (`logit r = "
                                              "logit r0 + sum_i (logit r_i - logit r0)`, "
                                              "`tracking.support.pooled_weights`; the fused "
                                              "density is unchanged; LMB peers' tentative "
                                              "tracks, `lmb.tentative_threshold`, add theirs); "
                                              "0: off; -1: 0.01 for LMB peers that publish "
                                              "tentative tracks, else off.",
                                    check=Bound(-1, 1, high_open=True))
    existence_young: int = option(2, doc="With `existence_prior`: how many scans old (its "
                                         "label's scan) a fused track may be and still be "
                                         "pooled.", unit="scans", check=NONNEGATIVE)
    existence_mature: int = option(-1, doc="Extraction of fused tracks (labelled peers): a "
                                           "track older than `existence_young` scans that "
                                           "two inputs or more hold weighs at most their "
                                           "existences pooled about its fused weight of the "
                                           "scan before times `Ps` "
                                           "(`tracking.mature_existence`), so a target every "
                                           "input just missed falls as in the centralised "
                                           "filter, not as the inputs' mean; 1: on, 0: off, "
                                           "-1 (auto): on with `existence_prior` on (LMB peers "
                                           "that publish tentative tracks) and a `rule` other "
                                           "than `\"gci\"` (its fused weights are a PHD's, not "
                                           "existences). Issue 33: 20 LMB "
                                           "peers' fused tracks outlived their targets by a "
                                           "scan or more (docs/labelled-tracking.md, \"Fused "
                                           "tracks outlive their targets\").",
                                   check=Bound(-1, 1))
    existence_absent: float = option(-1.0, doc="With `existence_mature`: an input holding no "
                                              "mass of a mature fused track counts in its pool "
                                              "at this existence (its own is below the "
                                              "threshold it publishes tracks from), instead of "
                                              "being left out (`tracking.mature_existence`); 0: "
                                              "off; -1 (auto): `lmb.tentative_threshold` for "
                                              "LMB peers. Issue 33: at a target's death some "
                                              "inputs hold it no more and the rest, each after "
                                              "one miss, kept it reported "
                                              "(docs/labelled-tracking.md, \"Inputs without the "
                                              "track count\").",
                                     check=Bound(-1, 1, high_open=True))
    label_fallback: int = option(-1, doc="Labels of fused tracks (labelled peers): a "
                                         "fused row that loses the label it won to a "
                                         "heavier row (two rows paired with one label; "
                                         "with AA, outside the gate of it) takes the next "
                                         "label it was paired with in the network rule's "
                                         "order that no row holds, instead of a fresh "
                                         "one, and its own track is released to it "
                                         "(`peers.labelling.next_labels`). Issue 34: a "
                                         "young aircraft's reported label gave way to a "
                                         "fresh one when a slow radar's track of its "
                                         "neighbour moved onto it (docs/real-traffic.md, "
                                         "\"The switches traced\"); 1: on, 0: off, -1 "
                                         "(auto): on for LMB peers with rotating radars "
                                         "(a `rotation_period`), off for the others (the "
                                         "GM-PHD peers' switches rose on real traffic, "
                                         "docs/real-traffic.md, \"Young fused tracks keep "
                                         "their labels\"; synchronous LMB cells: "
                                         "docs/labelled-tracking.md).",
                                 check=Bound(-1, 1))
    label_keep: int = option(-1, doc="Labels of fused tracks (labelled peers): a fused "
                                     "row paired with a label this peer reported the "
                                     "scan before does not take a label born its settle "
                                     "scans (the eccentricity, `peers.labelling."
                                     "settle_scans`) or more before that one, which is "
                                     "not the same target's label on its way but "
                                     "another's track passing by "
                                     "(`peers.labelling.kept_first`). Issue 34: a slow "
                                     "radar's earlier-born track beside a young aircraft "
                                     "took its reported row by the earliest-birth rule "
                                     "(docs/real-traffic.md, \"The switches traced\"); 1: "
                                     "on, 0: off, -1 (auto): on for LMB peers with rotating "
                                     "radars, off for the others (as `label_fallback`).",
                             check=Bound(-1, 1))
    existence_own: int = option(0, doc="Extraction of fused tracks (LMB peers with "
                                       "`existence_prior` on and an x-y `linear` sensor "
                                       "without rotation): a young track the pool raised "
                                       "and the peer's own tracks hold none of also weighs "
                                       "the peer's own scan, `1 - Pd + Pd sum_z N(z; Hm, "
                                       "HPH' + R) / kappa` on its existence odds "
                                       "(`tracking.own_scan`), so two neighbours' clutter "
                                       "tracks at one place meet the own sensor's miss, as "
                                       "in the centralised update; 1: on, 0: off. Issue 33 "
                                       "(docs/labelled-tracking.md, \"Young fused tracks "
                                       "and the peer's own scan\").", check=Bound(0, 1))
    existence_keep: bool = option(False, doc="With `existence_prior`: a fused track reported "
                                             "the scan before is pooled at any age, and a "
                                             "new label beside it cannot take its target "
                                             "(`tracking.support.pooled_weights` `keep`), so "
                                             "a track born by pooling stays while fewer "
                                             "peers than half the weight hold it (issue 34: "
                                             "far radars confirm aircraft late or never; "
                                             "docs/real-traffic.md, \"Fused births pooled "
                                             "across radars\").")
    existence_revisit: int = option(-1, doc="Extraction of fused tracks (labelled peers, "
                                            "rotating radars): a young track two inputs "
                                            "or more hold weighs its AA existence over "
                                            "the inputs whose radar could have confirmed "
                                            "it by its age (two looks: each radar's "
                                            "`rotation_period` from the scenario, "
                                            "`tracking.support.revisit_weights`), so a "
                                            "slow radar not yet looked at twice is no "
                                            "evidence against it (issue 34, "
                                            "docs/real-traffic.md, \"Why the far radars "
                                            "confirm late\"); 1: on, 0: off, -1 (auto): on "
                                            "for LMB peers with rotating radars, off for "
                                            "the others (as `label_fallback`); it acts "
                                            "only on sensors with a `rotation_period`.",
                                    check=Bound(-1, 1))
    stamp_twins: int = option(-1, doc="Extraction of fused tracks (labelled peers with a "
                                     "peer 2 hops or more away): a row whose label is at "
                                     "most this many scans old is not reported while the "
                                     "peer's fused density holds, or held in the last as "
                                     "many scans, a label of the same origin and index born "
                                     "up to as many scans earlier within the hybrid gate of "
                                     "it: a stamp moved a scan later for want of "
                                     "corroboration, whose first may still come from a far "
                                     "peer and take the id (`tracking.label_twins`; the fused "
                                     "density and labels are unchanged); 0: off; -1 (auto): 1 "
                                     "for LMB peers (chosen on training runs, evaluated "
                                     "once), off for the others. Issue 33 "
                                     "(docs/labelled-tracking.md, \"One target, two stamps "
                                     "a scan apart\").", unit="scans", check=at_least(-1))
    id_blocks: int = option(0, doc="Reported ids of fused tracks (labelled peers): a shared "
                                   "label is reported as its block, its scan rounded down to a "
                                   "multiple of this many scans and its birth cell's numbers "
                                   "to multiples of as many cells, so the stamps one target "
                                   "gets a scan apart or in neighbouring cells, which the "
                                   "network rule settles a hop a scan, show one id "
                                   "(`tracking.stamp_blocks`; the fused density, its labels "
                                   "and what peers send are unchanged); 0: off. Issue 33 "
                                   "(docs/labelled-tracking.md, \"One id for a target's "
                                   "first stamps\").", unit="scans", check=NONNEGATIVE)
    label_hold: int = option(0, doc="Fused extraction (labelled peers): a reported row whose "
                                    "label is at most `existence_young` scans old and that the "
                                    "peer did not report in the last this many scans is "
                                    "reported under an earlier-born label it did report then, "
                                    "not reported now, whose fused row lies within the label "
                                    "gate of it (`tracking.held_ids`; the fused density and "
                                    "labels are unchanged); 0: off. Issue 34: with "
                                    "`lmb.tentative_threshold` a row pooled from two radars' "
                                    "one-plot tracks replaced an aircraft's id "
                                    "(docs/real-traffic.md, \"The tentative route's switches "
                                    "traced\").", unit="scans", check=NONNEGATIVE)
    label_keep_scans: int = option(0, doc="With `label_keep`: the labels it keeps are those "
                                          "this peer reported in the last this many scans "
                                          "(and the last scan it reported), not only the "
                                          "scan before, so a reported track not extracted "
                                          "for a scan keeps its veto (`tracking.held_ids."
                                          "ReportedIds`; the fused density is unchanged); 0: "
                                          "off (the scan before only). Issue 34: a mature "
                                          "aircraft's row pooled below 0.5 for one scan lost "
                                          "its label to a far radar's remnant of another "
                                          "aircraft's (docs/real-traffic.md, \"The tentative "
                                          "route's switches traced\").", unit="scans",
                                   check=NONNEGATIVE)
    trust: bool = option(True, doc="Test each neighbour's density before fusing it and "
                                   "down-weight or quarantine the inconsistent ones "
                                   "(`peers.trust`; on by default since issue 36 item 5: "
                                   "clean runs lose nothing measurable, docs/security.md).")
    trust_register: bool = option(True, doc="With `trust`: repair a neighbour the offset test "
                                             "fires on (registration, `TrustConfig.register`) "
                                             "instead of quarantining it.")
    trust_repair: bool = option(True, doc="With `trust`: fuse a failing neighbour's repaired "
                                          "density (its uncorroborated components dropped, its "
                                          "mass the others' median) where that passes the test "
                                          "(`TrustConfig.repair`).")
    lie: str = option("", doc="Test hook: `\"PEER:KIND\"` makes that peer publish lie KIND of "
                              "`sim.run.lies` in every estimate (a member lying with its own valid "
                              "key), in the twin and as a process.", custom="no lie")


@dataclass(frozen=True)
class NetworkSpec:
    """The peer network: one peer per sensor (same name), its graph, consensus and pacing."""

    topology: str = option("full", doc="`\"full\"`, `\"ring\"`, `\"star\"` (hub: "
                                       "`fusion.fusing_sensor`), `\"line\"` or `\"custom\"` "
                                       "(`edges`).", choices=TOPOLOGIES)
    edges: tuple[tuple[str, str], ...] = option(
        (), doc="Undirected edges between sensor names, `[[\"s1\", \"s2\"], ...]` (topology "
                "`\"custom\"` only).", custom="none")
    rounds: int = option(1, doc="Consensus (or flooding) rounds `L` per scan.",
                         check=Bound(1, MAX_ROUNDS))
    omega: str = option("metropolis", doc="The peers' fusion weights: `\"metropolis\"`, "
                                          "`\"uniform\"`, or each pair's optimised `\"det\"` / "
                                          "`\"chernoff\"` weight (GCI; consensus then "
                                          "Metropolis).", choices=OMEGA_RULES)
    max_age: int = option(5, doc="Neighbour estimates older than this are not fused.",
                          unit="scans", check=NONNEGATIVE)
    policy: str = option("nale", doc="Out-of-sequence policy: `\"nale\"`, `\"drop-late\"` or "
                                     "`\"as-is\"`.", choices=OOS_POLICIES)
    feedback: bool = option(False, doc="Peers use their fused density as the prior of the next "
                                       "scan.")
    speed: float = option(10.0, doc="Wall-clock speed factor: a scan every `scan_period / "
                                    "speed` seconds.", check=POSITIVE)
    birth_ids: str = option(
        "shared", doc="GM-PHD and LMB peers' ids of births: `\"shared\"`, made alike at "
                      "every peer (origin 0, the scan of first publication, the birth "
                      "component, or for an LMB's adaptive birth the `lmb.birth_cell` grid "
                      "cell of its plot: `tracking.label_keys.SHARED_ORIGIN`; the peers' own "
                      "origins then start at 1), or `\"own\"` (the peer's origin; the network "
                      "rule spreads the winner over the graph). GM-PHD measurement births "
                      "(`birth.model` `\"measurements\"`) are always own.",
        choices=("shared", "own"))
    label_support: bool = option(
        True, doc="LMB peers with `birth_ids` `\"shared\"`: a tie between shared ids "
                  "of one scan (a target's first plots in two birth cells) goes to the id "
                  "more peers stamped, not the lowest cell (`peers.label_support`: each "
                  "label's stamping peers as a bit mask, OR-ed over the neighbours'). On by "
                  "default since issue 33: 20 LMB peers' fused OSPA(2) 28.7 -> 25.4 and 44.1 "
                  "-> 41.0 m on training runs (docs/labelled-tracking.md); false: lowest index. "
                  "Not for GM-PHD peers (their fixed births do not tie; the masks cost them "
                  "CPU).")
    filter: str = option("gmphd", doc="The peers' kind (`sim.kinds`): `\"gmphd\"`, "
                                      "`\"et-gmphd\"` (`[extended]`), for one target "
                                      "`\"imm-pf\"`/`\"imm-ekf\"`, `\"flooding\"` (seed 004, "
                                      "`[clustering]`) or `\"pda\"` (seed 003, `[pda]`).",
                         choices=kind_names)
    deadline: float = option(0.5, doc="Fusion deadline after a scan.", unit="scan interval",
                             check=Bound(0, 1, low_open=True))
    router: bool = option(False, doc="`sensornet run`/`demo`: every process a client of one "
                                     "Zenoh router the run starts (as `--router`), not peer to "
                                     "peer.")
    ros2: bool = option(False, doc="Each peer also publishes its tracks (and the world its "
                                   "detections) as ROS 2 messages in `rmw_zenoh`'s format "
                                   "(`--ros2`; docs/ros2.md; needs the `[ros2]` extra).")
    ros2_domain: int = option(0, doc="The ROS 2 domain (`ROS_DOMAIN_ID`) of those messages.",
                              check=Bound(0, 232))


@dataclass(frozen=True)
class ExtendedSpec:
    """Extended targets (seed 002, docs/seed002.md): returns per target and partitioning."""

    rate: float = option(10.0, doc="`gamma`: Poisson mean of the measurements of a detected "
                                   "target per scan.", check=POSITIVE)
    partition: str = option("distance", doc="`\"distance\"` (Granström, MST thresholds) or "
                                            "`\"grid-spectral\"` (the seed's method).",
                            choices=PARTITIONS)
    p_lower: float = option(0.3, doc="Distance partitioning: lower chi-square(2) probability of "
                                     "the thresholds on `d^2/2`.", check=PROBABILITY)
    p_upper: float = option(0.8, doc="Distance partitioning: upper chi-square(2) probability "
                                     "(at least `p_lower`).", check=PROBABILITY)
    compression: float = option(0.5, doc="Grid-spectral: compression rate `gamma` of the grid "
                                         "(seed 002 eq. 5).", check=Bound(0, 2, low_open=True))
    cell_factor: float = option(4.0, doc="Grid-spectral: `c0` in `ceil(N_z^(gamma/2) c0)` cells "
                                         "per axis (our reading).", check=POSITIVE)
    core_level: float = option(0.5, doc="Grid-spectral: core threshold `min + core_level (max "
                                        "- min)` of the cell counts.", check=PROBABILITY)
    rho: float = option(2.0, doc="Grid-spectral: density parameter of the edge length "
                                 "`rho^dist - 1`.", check=Bound(1, low_open=True))
    k_rule: str = option("eigengap", doc="Grid-spectral: number of clusters by `\"eigengap\"` "
                                         "or `\"core-regions\"`.", choices=K_RULES)
    k_spread: int = option(0, doc="Grid-spectral: also partitions for K +- 1..k_spread (0: one "
                                  "partition, the paper's).", check=NONNEGATIVE)
    units: str = option("sigma", doc="Grid-spectral: distances in `\"sigma\"` units or the "
                                     "paper's `\"unit-box\"` [0, 1].", choices=DISTANCE_UNITS)
    max_measurements: int = option(2000, doc="Scans with more points are not partitioned "
                                             "(counted, corrected as all-missed).",
                                   check=at_least(1))


@dataclass(frozen=True)
class ClusteringSpec:
    """Flooding peers' clustering (seed 004, ``tracking.idpc``; ``[clustering]`` table)."""

    cutoff: float = option(25.0, doc="`d_c`, the neighbourhood radius.", unit="m",
                           check=POSITIVE)
    zeta: float = option(0.3, doc="Target points have more than `zeta S` neighbours within "
                                  "`d_c`.", check=POSITIVE)
    radius_factor: float = option(1.25, doc="`L`: a cluster takes the points within `L d_c` of "
                                            "its seed.", check=POSITIVE)
    split_factor: float = option(1.6, doc="Clusters above `split_factor S Pd` points are split "
                                          "by k-means.", check=POSITIVE)
    assumed_scans: str = option("held", doc="`S`: the scans a peer holds (`\"held\"`) or every "
                                            "sensor (`\"all\"`).", choices=ASSUMED_SCANS)
    estimator: str = option("idpc", doc="The flooding peers' estimator from the pooled scans: "
                                        "`\"idpc\"` (density-peaks clustering), `\"ftc\"` "
                                        "(DBSCAN + k-means) or `\"ic\"` (the iterated-corrector "
                                        "GM-PHD, `[filter]`/`[birth]`, corrected with each "
                                        "pooled scan in turn; `peers.flooding."
                                        "IcFloodEstimator`). Seed 004's `flooding.estimator`.",
                            choices=FLOOD_ESTIMATORS)


@dataclass(frozen=True)
class LmbSpec:
    """LMB peers' measurement-driven birth (Reuter, Vo, Vo & Dietmayer 2014, Sec. IV-C).

    ``network.filter = "lmb"`` (:mod:`sim.kinds.lmb`, ``tracking.lmb``); ``[lmb]`` table. The
    defaults are :class:`tracking.lmb.LmbFilter`'s."""

    birth_rate: float = option(0.1, doc="`lambda_B`: expected adaptive births per scan; each "
                                        "measurement `z` gives a birth of existence "
                                        "`min(r_B,max, lambda_B (1 - r_U(z)) / max(1, "
                                        "sum_z' (1 - r_U(z'))))` (Reuter eq. 31; `r_U(z)`: "
                                        "`z`'s probability of belonging to a track), so the "
                                        "births of a scan add up to at most `lambda_B`.",
                               check=NONNEGATIVE)
    birth_max_existence: float = option(0.1, doc="`r_B,max`: the largest existence of one "
                                                 "adaptive birth.", check=PROBABILITY)
    tentative_threshold: float = option(0.15, doc="Also publish young tracks (label at most "
                                                  "`tentative_scans` scans old) of existence "
                                                  "above this (below `fusion.level2_threshold`), "
                                                  "for `fusion.existence_prior` to pool; 0: "
                                                  "only tracks above `fusion.level2_threshold` "
                                                  "(and no pooling). 0.15 by default since "
                                                  "issue 33: with `tentative_gap` 0 it removes "
                                                  "most fused birth latency without confirmed "
                                                  "switches (training runs: fused OSPA(2) 33.7 / "
                                                  "47.4 / 36.0 / 48.0 -> 27.4 / 40.5 / 30.9 / "
                                                  "44.0 m, seed 000 and 20 peers, Pd 0.99 / 0.9).",
                                        check=PROBABILITY)
    tentative_scans: int = option(2, doc="With `tentative_threshold`: how many scans old a "
                                         "track may be and still be published as tentative.",
                                  unit="scans", check=NONNEGATIVE)
    republish_gap: int = option(-1, doc="A published track label that returns after more than "
                                        "this many scans unpublished is stamped anew at first "
                                        "publication (as GM-PHD peers do); -1: never.",
                                unit="scans", check=at_least(-1))
    tentative_gap: int = option(0, doc="The same for a label only ever published as "
                                       "tentative (`tentative_threshold`); -1: "
                                       "`republish_gap`. 0 by default: a tentative track that "
                                       "went unpublished and came back is stamped anew (else a "
                                       "clutter track's early tentative stamp can return and "
                                       "replace a target's confirmed id).", unit="scans",
                                check=at_least(-1))
    corroborate_scans: int = option(0, doc="Scans after its first publication in which an own "
                                           "label that no neighbour's track was paired with "
                                           "(uncorroborated) moves a scan later, every scan "
                                           "(`peers.labelling.corroborated`); 1: only in the "
                                           "scan of its first publication (as GM-PHD peers); "
                                           "0: 3 when `tentative_threshold` is on, else 1 "
                                           "(issue 33: a clutter track one peer published "
                                           "tentatively scans before a target's others no longer "
                                           "gives the target its id; training runs, 20 peers, Pd "
                                           "0.99: fused OSPA(2) 30.9 -> 28.7 m).",
                                    unit="scans", check=NONNEGATIVE)
    birth_cell: float = option(200.0, doc="With `network.birth_ids` `\"shared\"`: width of "
                                          "the grid cells whose index labels an adaptive birth "
                                          "alike at every peer (edges at multiples of it).",
                               unit="m", check=POSITIVE)
    birth_edge: float = option(0.0, doc="With `network.birth_ids` `\"shared\"`: an adaptive "
                                        "birth whose plot lies within this distance of an edge "
                                        "of its `birth_cell` cell is stamped at first "
                                        "publication with the next scan, so that a stamp of the "
                                        "neighbouring cell (another peer's plot across the "
                                        "edge) loses the tie to the stamps of plots well inside "
                                        "a cell; 0: off (the default: better on the training "
                                        "runs, not on the evaluation runs, issue 33); -1: the "
                                        "sensor's position noise (standard deviation) when "
                                        "`tentative_threshold` is on, else off.", unit="m",
                               check=at_least(-1))
    birth_velocity_std: float = option(30.0, doc="Standard deviation of each velocity "
                                                 "component of an adaptive birth (mean 0; its "
                                                 "position is the measurement's).", unit="m/s",
                                       check=POSITIVE)
    time_slice: float = option(0.0, doc="Plots at their own times (issue 34, recorded "
                                        "traffic): the world sends each plot's age with the "
                                        "scan and the peer takes a rotating radar's plots in "
                                        "slices of this length at the slice's midpoint "
                                        "(sector `Pd` and clutter, as the asynchronous "
                                        "centralised reference; `peers.lmb_own_times`), then "
                                        "predicts to the tick; divides `scenario.scan_period`. "
                                        "0: every plot at its tick.", unit="s",
                               check=NONNEGATIVE)
    fused_extraction: str = option("auto", doc="How an LMB peer reports tracks from its "
                                                 "fused density: `\"filter\"` "
                                                 "(`filter.extraction`), `\"round\"` (every "
                                                 "fused track heavier than "
                                                 "`filter.extraction_threshold`: an existence "
                                                 "test per track, as the LMB's own rule) or "
                                                 "`\"cardinality\"` (the `round` of the total "
                                                 "mass heaviest). The hybrid's mass is the "
                                                 "average of the peers' (AA), so when far "
                                                 "peers hold fewer targets the total runs "
                                                 "short and `\"cardinality\"` drops a target "
                                                 "7 of 8 peers hold (issue 34, "
                                                 "docs/real-traffic.md). `\"auto\"` "
                                                 "(default): `\"round\"` (issue 33, evaluated "
                                                 "on the synthetic LMB graphs: "
                                                 "docs/labelled-tracking.md), `\"filter\"` under "
                                                 "`fusion.rule` `\"gci\"`, whose fused weights "
                                                 "are a PHD's, a target's mass split over "
                                                 "components (docs/labelled-tracking.md, \"The "
                                                 "GCI and AA rules under the LMB defaults\").",
                                     choices=("auto", "filter", *EXTRACTION_RULES))
    aa_label_existence: str = option("auto", doc="Under `fusion.rule` `\"aa\"`, how an "
                                                   "LMB peer's fused extraction treats each "
                                                   "input's copy of a target (kept at weight "
                                                   "`w_i r_i`, so three inputs' 0.9 are three "
                                                   "rows at 0.3): `\"mean\"` reports a label "
                                                   "once at its copies' summed existence "
                                                   "(capped at 1; Li 2022's per-label AA) and "
                                                   "their weighted mean state, `\"heaviest\"` "
                                                   "the same existence at the labelled row's "
                                                   "state, `\"off\"` each row by its own "
                                                   "weight. Extraction only: the fused "
                                                   "density and the estimates peers send "
                                                   "are unchanged, the reported tracks not. "
                                                   "`\"auto\"` (default): `\"mean\"` "
                                                   "(issue 33, chosen on training runs, "
                                                   "evaluated once: docs/labelled-tracking.md, "
                                                   "\"Per-label existence over the AA "
                                                   "copies\").",
                                     choices=("auto", "off", "mean", "heaviest"))
    adopt_states: int = option(-1, doc="What an LMB peer takes from its fused density as "
                                       "the next prior (feedback). With `network.feedback`, "
                                       "0: all of it (the fused density becomes its LMB); "
                                       "n > 0 (feedback on): only the fused states of its "
                                       "own tracks whose label is more than n scans old, "
                                       "their existence, its young and other tracks staying "
                                       "its own, and its labels relabelled as without "
                                       "feedback (diffusion of the hybrid's "
                                       "covariance-intersection states, Hu, Xie & Zhang "
                                       "2012; `peers.lmb_estimator`); -1 (auto): "
                                       "`fusion.existence_young` (young tracks stay "
                                       "independent evidence for the pool) for peers with a "
                                       "peer 2 hops or more away (with every peer a "
                                       "neighbour one round already fuses every input) under "
                                       "the `\"hybrid\"` rule with sensors that scan every "
                                       "tick (no `rotation_period`, no `lmb.time_slice`), "
                                       "else 0. Issue 33 (docs/labelled-tracking.md, \"Where "
                                       "the fused LMB's latency is, and what did not close "
                                       "it\").", unit="scans", check=at_least(-1))
