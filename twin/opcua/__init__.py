"""The twin on OPC UA (issue 27): `longwall serve` publishes a running face (server), modelled on OPC 40561
(address_space); who may connect (access)."""
