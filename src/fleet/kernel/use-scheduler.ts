import { createContext, useContext } from 'react';
import { pageScheduler, type Scheduler } from './scheduler';

/** The scheduler the views below use (the page's unless a test provides another). */
export const SchedulerContext = createContext<Scheduler>(pageScheduler);

export function useScheduler(): Scheduler {
  return useContext(SchedulerContext);
}
