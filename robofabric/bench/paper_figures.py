"""The paper's published data-usage figures (Tables 2 and 3), as printed, with where each comes from.

The paper streamed LIDAR scans from Unity to MATLAB through Firebase's REST API: 726 numbers a message
(240 rays) at a variable 600-800 Hz (Table 2, Fig. 11), then 415 numbers a message (135 rays) at 10-200 Hz
(Table 3, Fig. 12), each rate for two hours, statistics per minute. Its MB are taken as 10^6 bytes (Table 3's
200 Hz row: 97.07 MB/min x 60 = 5.82 GB against the 5.791 GB it prints; 2^20 would give 5.69).

Kept as printed, inconsistencies included: Table 3's 10 Hz minimum (5.5 MB) is above its average (4.79 MB).
``bytes_per_msg_implied`` is derived here, not printed: the average per minute over (rate x 60) messages.
"""

from __future__ import annotations

__all__ = ["PAPER", "PAPER_MULTI_USER", "paper_rows", "paper_resources"]

PAPER_SOURCE = (
    "Unity-MATLAB multi-user robotic simulation framework (the paper in /work/shared/reference), "
    "Firebase REST API, statistics per minute over a 2-hour trial per rate"
)

# rate -> (max MB/min, avg MB/min, min MB/min, GB in 1 h), Table 3 columns; 600 Hz from Table 2 (GB: 5.936 for
# "the time interval", Fig. 11's hour).
_TABLE3 = {
    10: (6.31, 4.7922, 5.5, 0.288),
    20: (12.75, 10.0590, 7.49, 0.604),
    50: (27.07, 24.2209, 21.36, 1.458),
    100: (63.8, 49.8041, 0.0, 3.019),
    200: (108.63, 97.0666, 47.26, 5.791),
}
_TABLE2 = (163.61, 139.28, 0.0, 5.936)


def paper_rows() -> list[dict]:
    """One row per rate the paper published, with its source (table, column) and the payload it streamed."""
    rows: list[dict] = []
    for rate, (mx, avg, mn, gb) in _TABLE3.items():
        rows.append(
            {
                "source": f"Table 3, {rate} Hz column",
                "transport": "firebase (REST)",
                "rate_hz": rate,
                "payload": "135 rays, 415 data points",
                "mb_per_min_max": mx,
                "mb_per_min_avg": avg,
                "mb_per_min_min": mn,
                "gb_per_hour": gb,
                "bytes_per_msg_implied": round(avg * 1e6 / (rate * 60)),
            }
        )
    mx, avg, mn, gb = _TABLE2
    rows.append(
        {
            "source": "Table 2 (600 Hz; the text: a variable 600-800 Hz)",
            "transport": "firebase (REST)",
            "rate_hz": 600,
            "payload": "240 rays, 726 data points",
            "mb_per_min_max": mx,
            "mb_per_min_avg": avg,
            "mb_per_min_min": mn,
            "gb_per_hour": gb,
            "bytes_per_msg_implied": round(avg * 1e6 / (600 * 60)),
        }
    )
    return rows


# Table 4: (application, computer) -> (CPU min %, CPU max %, RAM min MB, RAM max MB); its GB taken as 1,000 MB.
_TABLE4 = {
    ("Unity Editor-Meca500", "consumer"): (30.1, 35.7, 753.3, 763.1),
    ("Unity Editor-Reeman", "consumer"): (24.9, 27.1, 539.7, 744.5),
    ("MATLAB-Meca500", "consumer"): (1.5, 3.8, 1630.0, 1660.0),
    ("MATLAB-Reeman", "consumer"): (27.9, 37.3, 1711.0, 1751.0),
    ("Unity Editor-Meca500", "professional"): (27.0, 30.1, 1314.0, 1314.0),
    ("Unity Editor-Reeman", "professional"): (22.5, 25.6, 1316.0, 1316.0),
    ("MATLAB-Meca500", "professional"): (1.4, 2.8, 1752.0, 1761.0),
    ("MATLAB-Reeman", "professional"): (36.9, 43.1, 1814.0, 1837.0),
}


def paper_resources() -> list[dict]:
    """Table 4 as printed, one row per application and computer (its CPU is presumably a share of the whole machine,
    16 or 8 cores, as Windows reports it; the paper does not say)."""
    return [
        {
            "source": f"Table 4, {app}, {pc}-grade computer",
            "application": app,
            "computer": pc,
            "cpu_min": a,
            "cpu_max": b,
            "rss_min_mb": c,
            "rss_max_mb": d,
        }
        for (app, pc), (a, b, c, d) in _TABLE4.items()
    ]


PAPER_MULTI_USER: dict = {
    "source": "Section 3.3: 5 of the PUN server's 20 concurrent users for 2 h; 'all users had a 100 ms delay when "
    "interacting with non-owned network objects' (how it was measured is not said)",
    "users": 5,
    "hours": 2.0,
    "delay_ms": 100.0,
}
"""The paper's multi-user test as published: the ``paper_reported`` member of ``multi_user``."""

PAPER: dict = {
    "source": PAPER_SOURCE,
    "mb": "10^6 bytes",
    "data_usage": paper_rows(),
    "resources": paper_resources(),
    "multi_user": PAPER_MULTI_USER,
}
"""The ``paper`` member of ``bench paper --json``."""
