"""The aberman2020 motion translator: networks (``model``), data (``data``), training
(``train``; run ``python -m training.translator``)."""
