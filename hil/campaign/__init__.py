"""Campaigns: many seeded batch runs on Dask, and the scenarios they draw (``boundswarm
campaign``, ``boundswarm generate``).

    spec.py         campaign specs (TOML) expanded into runs
    run.py          one run: its description -> a scenario -> the batch simulator -> a row
    driver.py       running a campaign on Dask into a campaign folder, resumable
    report.py       a campaign's report and figures from its rows
    families.py     seeded scenario families and micro cases, as scenario documents
    micro_cases.py  the micro cases: small situations that break naive controllers
    scene.py        a generated scenario's geometry and its scenario document
"""
