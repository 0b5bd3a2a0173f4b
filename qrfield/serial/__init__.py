"""The serial link to the gripper controller: protocol 2 of docs/conventions.md.

Modules, each with one job (docs/architecture.md):

- :mod:`qrfield.serial.codec`: the only place that knows the line format: encoding and decoding of
  ``$QRF``, ``$QRM``, ``$QRA`` and ``$QRC`` lines, CRC-16/CCITT-FALSE, the number grammar (no I/O);
- :mod:`qrfield.serial.port`: opening a port: which names are accepted, exclusivity (a lock on the
  device), who holds a busy port, the list of ports;
- :mod:`qrfield.serial.link`: the port's own thread: pacing (newest pose first, by baud and the
  driver's queue), answers ahead of poses, NOSRC and STALE, reconnecting;
- :mod:`qrfield.serial.controller`: the controller's commands (PING, HELLO, STREAM, RATE, MEAS, ...)
  answered in order, and :class:`~qrfield.serial.controller.GripperLink`, a frame loop's sink (its
  poses in the chosen frame);
- :mod:`qrfield.serial.handeye`: ``$QRC,TOOL`` and ``$QRC,HANDEYE``: hand-eye pairs and their solve;
- :mod:`qrfield.serial.robot_demo`: the serial hand-eye workflow with a simulated robot and a
  scripted controller (``qrfield serial-demo --robot``);
- :mod:`qrfield.serial.relay`: a UART-speed relay between two ptys (the twin of a real UART's
  pace, for tests and ``qrfield benchmark serial``).

Nothing is imported here, so ``import qrfield.serial.codec`` stays light (no pyserial, no threads).
"""
