"""Private helpers every layer may use (and which import nothing else of the package):
the one error family (``_errors``), argument checks and did-you-mean (``_checks``), atomic file writes (``_files``),
interrupts (``_interrupts``), keyword checks (``_kwargs``), the parallel map
(``_parallel``) and compiled CasADi libraries (``_compiled``)."""
