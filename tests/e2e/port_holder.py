"""A gRPC server as every gRPC server is by default (SO_REUSEPORT on), holding a port for
test_taken_ports.py: ``python port_holder.py`` prints its port and serves until killed."""

from __future__ import annotations

import asyncio

import grpc
from grpc_health.v1 import health, health_pb2_grpc


async def main() -> None:
    server = grpc.aio.server()  # grpc's default options: the port may be shared
    health_pb2_grpc.add_HealthServicer_to_server(health.aio.HealthServicer(), server)
    port = server.add_insecure_port("127.0.0.1:0")
    await server.start()
    print(port, flush=True)
    await server.wait_for_termination()


if __name__ == "__main__":
    asyncio.run(main())
