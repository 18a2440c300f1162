"""Tooling around the guidance node, apart from it (as nav2 keeps its system tests and tester
nodes apart): the truth simulator (``sim``), the closed loop (``closed_loop``), dispersion
campaigns (``campaigns``, ``campaign_results``, ``campaign_executors``, ``campaign_plot``,
``campaign_cli``: ``daddy_campaign``), the closed-loop demo (``demo``: ``gnc_demo``) and the MCAP
recorder (``recording``)."""
