"""The lying-member study (docs/security.md): a member lying about its own estimate, on the
twin (:mod:`.study`), and the trust thresholds' calibration on clean runs
(:mod:`.trust_calibration`)."""
