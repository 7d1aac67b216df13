"""The translator: networks (``networks``), Bandai's aligned pairs (``pairs``), training
(``fit``) and the shipped model's schedule (``schedule``; run ``python -m
training.translator``)."""
