"""The live calibration page (``python -m aicalib_tf.live``): a camera feed in a browser, the guided loop behind it.

:mod:`aicalib_tf.live.server` holds the aiohttp application; ``page.html`` the page.
"""
