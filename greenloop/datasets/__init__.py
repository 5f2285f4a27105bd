"""Sequence folders: the one data contract every stage reads (``sequence``; other ground-truth
files in ``groundtruth_formats``), and the builders that write one: the embedded synthetic
greenhouse (``synthetic``), the real Nordland journey (``nordland``), Gardens Point Walking
(``gardenspoint``) and the real GreenHouse set's download (``greenhouse``)."""
