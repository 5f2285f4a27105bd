"""CNN backbones that Keras does not ship, as Keras 3 ports (``ghostnet``, ``shufflenet``,
``efficientnet_lite``), Google's ImageNet MobileNet TFLite graphs (``mobilenet_tflite``), and the
reader of PyTorch checkpoints that loads their ImageNet weights without torch (``torch_weights``).
``greenloop.features`` turns them into descriptors."""
