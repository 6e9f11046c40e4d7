"""The run: the pipeline, jobs, frame ranges, reuse, memory, warm-up, clusters and comparisons."""
