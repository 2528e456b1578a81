import threading
from types import SimpleNamespace

from snakemake.scheduling.job_scheduler import JobScheduler

from denali_pipe.workflow.scheduler_timer import PATCHED, keep_one_reevaluation_timer


def test_the_scheduler_keeps_one_pending_daemon_timer_whatever_triggers_its_passes():
    keep_one_reevaluation_timer()
    scheduler = SimpleNamespace(_open_jobs=threading.Semaphore(0))
    reevaluate = getattr(JobScheduler, PATCHED)
    before = threading.active_count()
    for _ in range(50):  # 50 passes (finished jobs) inside one timespan
        reevaluate(scheduler, 0.2)
    assert threading.active_count() == before + 1
    assert scheduler._denali_reevaluation.daemon  # the process exits without waiting for it
    assert scheduler._open_jobs.acquire(timeout=5)  # it fires once, one timespan on
    scheduler._denali_reevaluation.join()
    assert not scheduler._open_jobs.acquire(blocking=False)
    reevaluate(scheduler, 0.01)  # once it has fired, the next pass arms a new one
    assert scheduler._open_jobs.acquire(timeout=5)
