"""Layer 0, what every other layer stands on: the `Film` and `Stack` pytrees (`film`,
`stack`), what the exact paths take and how it is batched (`material`), the registry of
methods and what each models (`methods`), the checks at the public boundary (`_validate`),
atomic file writes (`_io`), JAX's persistent compilation cache (`compilation_cache`) and the
batch sharding over devices (`sharding`). Imports nothing else of the package."""
