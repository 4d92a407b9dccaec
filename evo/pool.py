"""The evaluation pool: keeps an executor's workers busy and hands back each outcome.

Both drivers of evaluations, the evolution (``evo.evolution.Evolution``) and the
retraining of fixed structures (``evo.retrain``, the noise ceiling), run through
:meth:`EvaluationPool.run`: it first submits the candidates a previous session left in
flight, then asks its driver for a new candidate whenever a worker is free, and hands
each outcome to the driver as it finishes (:func:`outcome_of`: a failed or
lost evaluation is an outcome with its error). Interrupted (a signal raised as
``evo.interrupt.Interrupted``, or any error), it stops the evaluations in flight with
``executor.terminate()`` instead of waiting for them; the driver has saved what it
needs to submit them again on resume. The driver decides what to submit and records
what comes back; the pool owns the waiting.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, wait

from evo.components.executors import EvalExecutor, EvaluationLost
from evo.evaluation import Job, Outcome, evaluate, first_line, one_line
from evo.run.files import WriteFailed
from evo.run.records import Candidate

Submission = tuple[Candidate, Job]
"""A candidate and the job it is evaluated under."""
NextCandidate = Callable[[Sequence[Candidate]], Submission | None]
"""Given the candidates in flight, the next one to submit, or None for none now."""
OnOutcome = Callable[[Candidate, Outcome], None]
"""Records one finished candidate's outcome."""


class EvaluationPool:
    """Evaluations of candidates on ``executor`` (see the module docstring).

    ``evaluate`` trains one candidate (``evo.evaluation.evaluate``; tests pass a cheaper
    one); it must be a module-level function, since executors pickle it.
    """

    def __init__(self, executor: EvalExecutor,
                 evaluate: Callable[[Candidate, Job], Outcome] = evaluate) -> None:
        self.executor, self.evaluate = executor, evaluate
        self.running: dict[Future[Outcome], Candidate] = {}

    def run(self, next_candidate: NextCandidate, on_outcome: OnOutcome,
            resumed: Sequence[Submission] = ()) -> None:
        """Evaluate ``resumed``, then every candidate ``next_candidate`` gives, until it
        gives none and nothing runs; then shut the executor down.

        ``on_outcome`` sees each outcome as its evaluation finishes, in the order they
        finish. An exception (``Interrupted`` included) terminates the executor, its
        evaluations in flight stopped, and propagates.
        """
        try:
            for submission in resumed:  # in flight when a previous session stopped
                self._submit(submission)
            while True:
                while len(self.running) < self.executor.workers:
                    following = next_candidate(list(self.running.values()))
                    if following is None:
                        break
                    self._submit(following)
                if not self.running:
                    break
                done, _ = wait(self.running, return_when=FIRST_COMPLETED)
                for future in done:
                    candidate = self.running.pop(future)
                    on_outcome(candidate, outcome_of(future, candidate, self.executor))
        except BaseException:
            self.executor.terminate()
            raise
        self.executor.shutdown()

    def _submit(self, submission: Submission) -> None:
        candidate, job = submission
        self.running[self.executor.submit(self.evaluate, candidate, job)] = candidate


def outcome_of(future: Future[Outcome], candidate: Candidate, executor: EvalExecutor) -> Outcome:
    """The outcome of a finished ``evaluate`` future; an evaluation lost on every attempt
    (its worker or node died each time) or an exception outside ``evaluate`` becomes an
    outcome with the error, in one line."""
    try:
        return future.result()
    except EvaluationLost as err:
        executor.restart()
        return Outcome(candidate.birth, candidate.name, error=f"evaluation lost: {one_line(err)}")
    except WriteFailed:
        raise  # the disk's fault: the run stops and resumes with the robot in flight
    except Exception as err:  # noqa: BLE001 - recorded, the caller goes on
        cause = getattr(err, "cause", None)  # Ray wraps a task's error (RayTaskError)
        if isinstance(cause, WriteFailed):
            raise WriteFailed(cause.errno, cause.strerror, cause.filename) from err
        return Outcome(candidate.birth, candidate.name, error=first_line(err))
