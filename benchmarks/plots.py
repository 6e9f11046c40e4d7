"""matplotlib for the benchmark plots only: a headless pyplot, or None (with a hint) when the
benchmark extras are not installed."""


def pyplot():
    try:
        import matplotlib
    except ImportError:
        print("matplotlib not installed: no plots (pip install -r requirements/bench.txt)")
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt
