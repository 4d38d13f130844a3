"""Transports: asyncio TCP and UDP listeners feeding sans-IO protocol sessions."""
