"""Study analysis: questionnaire scores, reading DATA.csv, the paper's tests and the report.

The stage's public names are re-exported here (``from simulator.analyze import ...``); each
submodule says what it holds.
"""

from __future__ import annotations

from simulator.analyze.data import Study, read_study, session_flow
from simulator.analyze.design import Design, design_table
from simulator.analyze.report import Analysis, analyze_study, write_report
from simulator.analyze.scores import (
    MSSQ_TYPES,
    SSQ_ITEMS,
    SSQ_MEMBERSHIP,
    MSSQScore,
    SSQScores,
    k_of,
    mssq_section_score,
    mssq_short_score,
    ssq_scores,
)
from simulator.analyze.stats import Statistics, StatsOptions, study_statistics
from simulator.core.choices import FLOW_STATS

__all__ = [
    "FLOW_STATS",
    "MSSQ_TYPES",
    "SSQ_ITEMS",
    "SSQ_MEMBERSHIP",
    "Analysis",
    "Design",
    "MSSQScore",
    "SSQScores",
    "Statistics",
    "StatsOptions",
    "Study",
    "analyze_study",
    "design_table",
    "k_of",
    "mssq_section_score",
    "mssq_short_score",
    "read_study",
    "session_flow",
    "ssq_scores",
    "study_statistics",
    "write_report",
]
