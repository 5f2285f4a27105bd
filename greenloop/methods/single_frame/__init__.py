"""The single-frame matcher: cosine of one frame's descriptor (any name of greenloop.features), and
per network its layer and pooling chosen on the tuning part."""
