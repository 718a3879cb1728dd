"""The study report: a self-contained HTML folder (summary, viewings, videos, viewing replay, analysis) and its loopback server."""
