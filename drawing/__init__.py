# SPDX-License-Identifier: GPL-3.0-or-later
"""GPU side of the extension: shader construction, texture packing and drawing (imports ``gpu``)."""
