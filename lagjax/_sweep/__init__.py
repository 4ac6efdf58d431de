"""Sweeps beyond one process's memory and lifetime: chunks streamed to a directory
(`store`, `to_disk`), resumed after a crash, shared among the processes of JAX's
distributed runtime (`processes`), with progress reports (`progress`)."""
