"""The fault-injection campaign of the guidance node and the core (test tooling, not product):
``make reliability`` runs it in full, test/test_reliability.py its CI subset."""
