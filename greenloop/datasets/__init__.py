"""Sequence folders: the one data contract every stage reads (``sequence``), and the builders
that write one: the embedded synthetic greenhouse (``synthetic``), the real Nordland journey
(``nordland``) and the real GreenHouse set's download (``greenhouse``)."""
