"""Model versus measurement (docs/model-vs-measurement.md).

:mod:`.logs` (flight logs) -> :mod:`.compare` (the residual, where it fails) ->
:mod:`.diagnose` (which effect is missing) and :mod:`.paperfits` (the paper's Sec. V.C
analyses) -> :mod:`.reports` (Markdown, PNG, JSON).
"""
