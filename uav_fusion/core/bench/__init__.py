"""The accuracy benchmark: a definition of generated flights (tune / test), their cache,
and the per-flight task that runs a profile and scores its fixed-rate output."""
