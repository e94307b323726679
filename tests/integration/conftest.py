from tests.integration.harness import make_probe, procs

__all__ = ["make_probe", "procs"]
