/* How much a waker pays to wake N sleeping processes, by mechanism.
 *
 *   cc -O2 -o /tmp/wake_mechanisms bench/wake_mechanisms.c
 *   /tmp/wake_mechanisms N ROUNDS MODE     (MODE 0: a datagram to each process's socket,
 *                                          as an iceoryx2 event notifies its listeners;
 *                                          1: one FUTEX_WAKE of all, as the shm wake word;
 *                                          2: one FUTEX_WAKE per process)
 *
 * N child processes sleep (in recv, or FUTEX_WAIT on a word in shared memory); each round
 * the parent waits 2 ms (so all sleep), wakes them all and times that part, wall and its
 * thread's CPU; then waits until every child has counted the round. Prints the per-process
 * means. Linux only. Behind the numbers in BENCHMARKS.md, "The wake word".
 */
#define _GNU_SOURCE
#include <stdio.h>
#include <stdlib.h>
#include <stdint.h>
#include <unistd.h>
#include <string.h>
#include <time.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/mman.h>
#include <sys/wait.h>
#include <linux/futex.h>
#include <sys/syscall.h>
#include <stdatomic.h>
static double now(){struct timespec t;clock_gettime(CLOCK_MONOTONIC,&t);return t.tv_sec*1e6+t.tv_nsec/1e3;}
static double cpu(){struct timespec t;clock_gettime(CLOCK_THREAD_CPUTIME_ID,&t);return t.tv_sec*1e6+t.tv_nsec/1e3;}
static long futex(void*a,int op,int v){return syscall(SYS_futex,a,op,v,NULL,NULL,0);}
int main(int argc,char**argv){
  if(argc!=4){fprintf(stderr,"usage: %s N ROUNDS MODE (N 1..64; MODE 0, 1 or 2)\n",argv[0]);return 2;}
  int n=atoi(argv[1]); int rounds=atoi(argv[2]); int mode=atoi(argv[3]);
  if(n<1||n>64||rounds<1||mode<0||mode>2){fprintf(stderr,"N 1..64, ROUNDS >= 1, MODE 0..2\n");return 2;}
  // shared: [0]=seq, [1]=acks
  _Atomic int *sh=mmap(0,4096,PROT_READ|PROT_WRITE,MAP_SHARED|MAP_ANONYMOUS,-1,0);
  int sv[64][2];
  for(int i=0;i<n;i++) socketpair(AF_UNIX,SOCK_DGRAM,0,sv[i]);
  for(int i=0;i<n;i++){ if(fork()==0){ int last=0; char b;
      for(int r=0;r<rounds;r++){
        if(mode==0){ recv(sv[i][1],&b,1,0); }
        else if(mode==1){ while(atomic_load(&sh[0])==last) futex(&sh[0],FUTEX_WAIT,last); }
        else { while(atomic_load(&sh[0])==last) futex(&sh[16+i],FUTEX_WAIT,0); }
        last=atomic_load(&sh[0]);
        atomic_fetch_add(&sh[1],1);
        futex(&sh[1],FUTEX_WAKE,1);
      } _exit(0);} }
  usleep(100000);
  double tw=0,tc=0; 
  for(int r=0;r<rounds;r++){
    usleep(2000); // let everyone block
    double w0=now(),c0=cpu();
    atomic_fetch_add(&sh[0],1);
    if(mode==0){ for(int i=0;i<n;i++) send(sv[i][0],"x",1,0);}
    else if(mode==1) futex(&sh[0],FUTEX_WAKE,INT32_MAX);
    else for(int i=0;i<n;i++) futex(&sh[16+i],FUTEX_WAKE,1);
    tw+=now()-w0; tc+=cpu()-c0;
    int target=(r+1)*n; int v;
    while((v=atomic_load(&sh[1]))<target) futex(&sh[1],FUTEX_WAIT,v);
  }
  printf("mode %s n %d: wall %.2f us/agent, cpu %.2f us/agent\n",mode==0?"socket":mode==1?"futex-bcast":"futex-each",n,tw/rounds/n,tc/rounds/n);
  while(wait(0)>0);
}
