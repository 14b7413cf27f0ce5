import ecmxf

with ecmxf.connect() as c:  # the socket as ecmxfctl finds it ($ECMXF_SOCKET, ...)
    print([(s.position, s.name, s.state) for s in c.slaves()])
    print("vendor id", hex(c.sdo_read(1, 0x1018, 1)))
    print(sum(1 for _ in c.stream_inputs(duration=1.0)), "input samples in 1 s")
