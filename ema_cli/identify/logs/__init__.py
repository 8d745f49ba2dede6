"""Log channels of the identifications: which columns a log holds, their units and column maps
(the file readers themselves live below every layer, in :mod:`ema_cli.logs`)."""
