"""Layer 0, what every other layer stands on: the `Film` pytree (`film`), the checks at the
public boundary (`_validate`), atomic file writes (`_io`), JAX's persistent compilation cache
(`compilation_cache`) and the batch sharding over devices (`sharding`). Imports nothing else of
the package."""
