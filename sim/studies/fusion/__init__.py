"""The fusion-quality study (docs/fusion-study.md): its campaign cells (:mod:`.quality`), the
study (:mod:`.study`) and the warnings its measurements back (:mod:`.advice`)."""
