"""One module per `uwgen` sub-command."""
