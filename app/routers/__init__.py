"""The HTTP API's routes, one ``APIRouter`` module per area; :func:`app.api.create_app`
composes them (with the batch router of :mod:`app.batch.api`, the middleware and the
exception handlers). Routes reach the app's state through :mod:`app.routers.deps` (the
store, the job service) and submit work as typed jobs (:mod:`app.jobs`) to
:class:`app.service.JobService`."""
