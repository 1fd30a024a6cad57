export { Lifecycle, type RunToken } from './lifecycle';
export { KernelSession, type PollSpec } from './session';
export { createSharedStore, replaceEqualDeep, withSharing } from './share';
export {
  defineCommands,
  useBlockedReason,
  type CommandSet,
  type CommandSpec,
  type Readable,
} from './commands';
export {
  MachineQueries,
  useMachineQuery,
  type Fetcher,
  type MachineQueriesOptions,
  type QueryOptions,
  type QueryView,
  type QueryWatch,
} from './query';
export {
  Deadline,
  ManualClock,
  pageScheduler,
  pageTimers,
  Scheduler,
  type Cancel,
  type DeadlineSpec,
  type TimerHost,
} from './scheduler';
export { SchedulerContext, useScheduler } from './use-scheduler';
